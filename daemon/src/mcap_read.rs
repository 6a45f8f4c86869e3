//! Reading chaosd's MCAP recordings back: the messages of each channel, the `chaosd` metadata,
//! and the CSV export (`chaosctl export FILE.mcap --csv`), row for row what a `.csv` recording
//! of the same run holds.

use crate::view::cdr::decode_joint_state;
use crate::view::Topic;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

/// One message: the row it belongs to (the MCAP sequence), its log time and its bytes.
#[derive(Clone, Debug)]
pub struct Message {
    pub row: u32,
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// A whole recording in memory.
#[derive(Debug, Default)]
pub struct McapFile {
    /// The `chaosd` metadata record (config, rate_hz, n, arm, clock_offset_ns).
    pub metadata: BTreeMap<String, String>,
    /// Messages per topic name, in file order.
    pub topics: BTreeMap<String, Vec<Message>>,
    /// Each topic's message encoding.
    pub encodings: BTreeMap<String, String>,
}

/// The replay channel's encoding before it was JSON (the text as it is): still read.
const OLD_REPLAY_ENCODING: &str = "chaosd-replay-2";

/// Whether `bytes` start like an MCAP file.
pub fn is_mcap(bytes: &[u8]) -> bool {
    bytes.starts_with(mcap::MAGIC)
}

/// Reads `path` whole.
pub fn read(path: &Path) -> Result<McapFile, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse(&bytes).map_err(|e| format!("{}: {e}", path.display()))
}

/// Parses a recording's bytes.
pub fn parse(bytes: &[u8]) -> Result<McapFile, String> {
    if !is_mcap(bytes) {
        return Err("not an MCAP file (no MCAP magic at its start)".into());
    }
    let mut file = McapFile::default();
    for rec in mcap::read::LinearReader::new(bytes).map_err(|e| e.to_string())? {
        if let mcap::records::Record::Metadata(m) = rec.map_err(|e| e.to_string())? {
            if m.name == crate::mcap_recording::METADATA {
                file.metadata = m.metadata;
            }
        }
    }
    for m in mcap::MessageStream::new(bytes).map_err(|e| e.to_string())? {
        let m = m.map_err(|e| e.to_string())?;
        file.encodings
            .entry(m.channel.topic.clone())
            .or_insert_with(|| m.channel.message_encoding.clone());
        file.topics
            .entry(m.channel.topic.clone())
            .or_default()
            .push(Message {
                row: m.sequence,
                log_time: m.log_time,
                data: m.data.into_owned(),
            });
    }
    Ok(file)
}

impl McapFile {
    /// The replay text of a `chaosd run --record` recording, tick after tick (empty when the
    /// file has no `/chaosd/replay` channel).
    pub fn replay_text(&self) -> Result<Vec<u8>, String> {
        let topic = Topic::Replay.name();
        let old = self.encodings.get(topic).map(String::as_str) == Some(OLD_REPLAY_ENCODING);
        let mut text = Vec::new();
        for m in self.messages(Topic::Replay) {
            if old {
                text.extend_from_slice(&m.data);
                continue;
            }
            let v: serde_json::Value = serde_json::from_slice(&m.data)
                .map_err(|e| format!("{topic}, row {}: {e}", m.row))?;
            let line = v["text"]
                .as_str()
                .ok_or_else(|| format!("{topic}, row {}: no \"text\" string", m.row))?;
            text.extend_from_slice(line.as_bytes());
        }
        Ok(text)
    }

    pub fn messages(&self, topic: Topic) -> &[Message] {
        self.topics.get(topic.name()).map_or(&[], Vec::as_slice)
    }

    /// Writes the CSV export; returns the rows written.
    pub fn to_csv(&self, out: &mut impl Write) -> Result<u64, String> {
        let json = |m: &Message| -> Result<serde_json::Value, String> {
            serde_json::from_slice(&m.data).map_err(|e| format!("row {}: {e}", m.row))
        };
        let by_row = |t: Topic| -> Result<BTreeMap<u32, serde_json::Value>, String> {
            self.messages(t)
                .iter()
                .map(|m| Ok((m.row, json(m)?)))
                .collect()
        };
        let (timing, residual, command) = (
            by_row(Topic::Timing)?,
            by_row(Topic::Residual)?,
            by_row(Topic::Command)?,
        );
        let states = self.messages(Topic::JointStates);
        let n = match states.first() {
            Some(m) => decode_joint_state(&m.data)?.position.len(),
            None => self
                .metadata
                .get("n")
                .and_then(|n| n.parse().ok())
                .unwrap_or(0),
        };
        let io = |e: std::io::Error| e.to_string();
        writeln!(out, "{}", crate::recording::csv_header(n)).map_err(io)?;
        let mut rows = 0;
        for m in states {
            let js = decode_joint_state(&m.data).map_err(|e| format!("row {}: {e}", m.row))?;
            let missing = |what: &str| format!("row {}: no {what} message", m.row);
            let t = timing
                .get(&m.row)
                .ok_or_else(|| missing("/chaosd/timing"))?;
            let r = residual
                .get(&m.row)
                .ok_or_else(|| missing("/chaosd/residual"))?;
            let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
            write!(
                out,
                "{:.6},{},{},{:.12e}",
                f(&t["t"]),
                t["state_seq"],
                t["state_stamp_ns"],
                f(&t["phi"])
            )
            .map_err(io)?;
            for v in js.position.iter().chain(&js.velocity) {
                write!(out, ",{v:.12e}").map_err(io)?;
            }
            match command.get(&m.row) {
                Some(c) => {
                    write!(out, ",{},{}", c["seq"], c["mode"]).map_err(io)?;
                    for k in 0..n {
                        write!(out, ",{:.12e}", f(&c["qdd"][k])).map_err(io)?;
                    }
                }
                None => write!(out, ",,{}", ",".repeat(n)).map_err(io)?,
            }
            writeln!(
                out,
                ",{:.9e},{:.9e},{:.9e},{:.9e},{}",
                f(&r["tracking_error"]),
                f(&r["period_residual"]),
                f(&r["null_residual"]),
                f(&r["mu"]),
                r["chaos"].as_str().unwrap_or("")
            )
            .map_err(io)?;
            rows += 1;
        }
        Ok(rows)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn what_is_not_mcap_is_refused_in_words() {
        let e = super::parse(b"t,state_seq\n1,2\n").unwrap_err();
        assert!(e.contains("not an MCAP file"), "{e}");
        let mut cut = mcap::MAGIC.to_vec();
        cut.extend_from_slice(&[1, 2, 3]);
        assert!(super::parse(&cut).is_err());
    }
}
