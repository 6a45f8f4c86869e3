//! The ROS 2 messages chaosd writes, in CDR (little-endian XCDR1, as ROS 2 sends them), and
//! the reader for the one chaosd reads back.
//!
//! `sensor_msgs/msg/JointState` is what every robotics tool plots and what Foxglove's and
//! Python's `mcap-ros2-support` decoders read without being told anything about chaosd. Two
//! messages do not justify a serialisation framework: the encoding is a handful of aligned
//! writes, and [`decode_joint_state`] checks every length against the buffer.

/// The CDR encapsulation header: little-endian plain CDR.
const HEADER: [u8; 4] = [0, 1, 0, 0];

/// A CDR writer over a reused buffer. Alignment counts from the end of the 4-byte header.
pub struct Cdr<'a> {
    buf: &'a mut Vec<u8>,
}

impl<'a> Cdr<'a> {
    /// Clears `buf` and starts a message in it.
    pub fn new(buf: &'a mut Vec<u8>) -> Self {
        buf.clear();
        buf.extend_from_slice(&HEADER);
        Self { buf }
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - HEADER.len()).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    pub fn strings(&mut self, v: &[String]) {
        self.u32(v.len() as u32);
        for s in v {
            self.string(s);
        }
    }

    pub fn f64s(&mut self, v: &[f64]) {
        self.u32(v.len() as u32);
        if !v.is_empty() {
            self.align(8);
        }
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }

    /// `builtin_interfaces/Time` from nanoseconds since the Unix epoch.
    pub fn time(&mut self, unix_ns: u64) {
        self.i32((unix_ns / 1_000_000_000) as i32);
        self.u32((unix_ns % 1_000_000_000) as u32);
    }
}

/// One joint state, as chaosd writes and reads it.
#[derive(Clone, Debug, PartialEq)]
pub struct JointState {
    pub stamp_ns: u64,
    pub frame_id: String,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

/// Encodes a `sensor_msgs/msg/JointState` into `buf`.
///
/// ```
/// # use daemon::view::cdr::{encode_joint_state, decode_joint_state};
/// let names = ["joint1".to_string(), "joint2".to_string()];
/// let mut buf = Vec::new();
/// encode_joint_state(&mut buf, 1_700_000_000_123_456_789, "base", &names, &[0.1, 0.2], &[1.0, 2.0], &[]);
/// let js = decode_joint_state(&buf).unwrap();
/// assert_eq!((js.stamp_ns, js.position.as_slice()), (1_700_000_000_123_456_789, &[0.1, 0.2][..]));
/// assert!(js.effort.is_empty());
/// ```
pub fn encode_joint_state(
    buf: &mut Vec<u8>,
    unix_ns: u64,
    frame_id: &str,
    names: &[String],
    position: &[f64],
    velocity: &[f64],
    effort: &[f64],
) {
    let mut w = Cdr::new(buf);
    w.time(unix_ns);
    w.string(frame_id);
    w.strings(names);
    w.f64s(position);
    w.f64s(velocity);
    w.f64s(effort);
}

/// Encodes a `std_msgs/msg/String` into `buf`.
pub fn encode_string(buf: &mut Vec<u8>, s: &str) {
    Cdr::new(buf).string(s);
}

/// A CDR reader with bounds checks.
struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn align(&mut self, n: usize) {
        let off = self.at - HEADER.len();
        self.at += (n - off % n) % n;
    }

    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let end = end.ok_or_else(|| format!("truncated at byte {}", self.at))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, String> {
        self.align(4);
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or([0; 4]),
        ))
    }

    fn count(&mut self, each: usize) -> Result<usize, String> {
        let n = self.u32()? as usize;
        if n.saturating_mul(each) > self.b.len() {
            return Err(format!(
                "a sequence of {n} does not fit in {} bytes",
                self.b.len()
            ));
        }
        Ok(n)
    }

    fn string(&mut self) -> Result<String, String> {
        let n = self.count(1)?;
        let s = self.take(n)?;
        let s = s.strip_suffix(&[0]).ok_or("a string without its NUL")?;
        String::from_utf8(s.to_vec()).map_err(|_| "a string that is not UTF-8".to_string())
    }

    fn f64s(&mut self) -> Result<Vec<f64>, String> {
        let n = self.count(8)?;
        if n > 0 {
            self.align(8);
        }
        (0..n)
            .map(|_| {
                Ok(f64::from_le_bytes(
                    self.take(8)?.try_into().unwrap_or([0; 8]),
                ))
            })
            .collect()
    }
}

/// Decodes a `sensor_msgs/msg/JointState` (little-endian CDR).
pub fn decode_joint_state(b: &[u8]) -> Result<JointState, String> {
    if b.get(..2) != Some(&HEADER[..2]) {
        return Err("not little-endian CDR".into());
    }
    let mut r = Reader {
        b,
        at: HEADER.len(),
    };
    let sec = r.u32()? as i32;
    let nsec = r.u32()?;
    let stamp_ns =
        u64::try_from(sec).map_err(|_| "a negative stamp")? * 1_000_000_000 + nsec as u64;
    let frame_id = r.string()?;
    let count = r.count(4)?;
    let name = (0..count).map(|_| r.string()).collect::<Result<_, _>>()?;
    Ok(JointState {
        stamp_ns,
        frame_id,
        name,
        position: r.f64s()?,
        velocity: r.f64s()?,
        effort: r.f64s()?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_and_arrays_are_aligned_as_ros_2_aligns_them() {
        let mut buf = Vec::new();
        let names = vec!["a".to_string()];
        encode_joint_state(&mut buf, 5_000_000_001, "", &names, &[1.5], &[], &[]);
        // sec, nsec | frame_id "" (len 1, NUL) | names: 1, "a" (len 2) | pad to 8 | ...
        let body = &buf[4..];
        assert_eq!(&body[0..8], &[5, 0, 0, 0, 1, 0, 0, 0]);
        assert_eq!(&body[8..13], &[1, 0, 0, 0, 0]);
        assert_eq!(&body[16..20], &[1, 0, 0, 0]);
        assert_eq!(&body[20..26], &[2, 0, 0, 0, b'a', 0]);
        assert_eq!(&body[28..32], &[1, 0, 0, 0]); // position count, then pad to 32
        assert_eq!(&body[32..40], &1.5f64.to_le_bytes());
        assert_eq!(decode_joint_state(&buf).unwrap().position, vec![1.5]);
    }

    #[test]
    fn truncated_or_lying_messages_are_refused() {
        let mut buf = Vec::new();
        let names = vec!["j".to_string(); 3];
        encode_joint_state(&mut buf, 1, "base", &names, &[1.0; 3], &[2.0; 3], &[3.0; 3]);
        for cut in 0..buf.len() {
            assert!(decode_joint_state(&buf[..cut]).is_err(), "cut at {cut}");
        }
        let mut lie = buf.clone();
        lie[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(decode_joint_state(&lie).is_err());
    }
}
