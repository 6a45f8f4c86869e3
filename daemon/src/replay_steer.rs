//! A steering handover as one line of a replay recording, and back, bit for bit: the planar
//! arm's (3 joints, perhaps a detour) or a spatial robot's (`MAX_JOINTS` joints, no detour).

use anyhow::{anyhow, bail, Result};
use control::steer::detour::MAX_DETOUR;
use control::steer::CycleTable;
use control::steer::DetourTable;
use control::steer::Steer;
use control::steer::{SpatialSteer, Steering, MAX_PHASES};
use protocol::MAX_JOINTS;

fn hex(v: f64) -> String {
    format!("{:016x}", v.to_bits())
}

fn bits(v: Option<&&str>, what: &str) -> Result<f64> {
    let v = v.ok_or_else(|| anyhow!("a steering record ends before its {what}"))?;
    if v.len() != 16 {
        bail!("steering {what} {v:?} is not 16 hex digits");
    }
    u64::from_str_radix(v, 16)
        .map(f64::from_bits)
        .map_err(|_| anyhow!("steering {what} {v:?} is not hex"))
}

/// `0`, or `1 t0 period kp kd k q…` (every f64 as its bits; `k` postures of 3 joints on the
/// planar arm, of `MAX_JOINTS` on a spatial one), then a planar detour's `D …` tail.
pub fn line(steering: Option<&Steering>) -> String {
    match steering {
        None => "0".into(),
        Some(Steering::Planar(s)) => {
            let mut out = cycle_line(&s.cycle, s.kp, s.kd);
            if let Some(d) = &s.detour {
                detour_line(&mut out, d);
            }
            out
        }
        Some(Steering::Spatial(s)) => cycle_line(&s.cycle, s.kp, s.kd),
    }
}

fn cycle_line<const N: usize>(cycle: &CycleTable<N>, kp: f64, kd: f64) -> String {
    let rows = cycle.rows();
    let mut out = format!(
        "1 {} {} {} {} {}",
        hex(cycle.t0),
        hex(cycle.period),
        hex(kp),
        hex(kd),
        rows.len()
    );
    for q in rows.iter().flatten() {
        out.push(' ');
        out.push_str(&hex(*q));
    }
    out
}

fn detour_line(out: &mut String, d: &DetourTable) {
    let pts = d.points();
    out.push_str(&format!(
        " D {} {} {} {}",
        hex(d.t_start),
        hex(d.duration),
        hex(d.t_arrive),
        pts.len()
    ));
    for q in pts.iter().flatten() {
        out.push(' ');
        out.push_str(&hex(*q));
    }
}

/// The `D ts duration t_arrive m p…` tail of a handover with a detour.
fn detour(f: &[&str]) -> Result<Option<DetourTable>> {
    if f.is_empty() {
        return Ok(None);
    }
    if f[0] != "D" {
        bail!("a steering record's tail starts with D (a detour)");
    }
    let (ts, dur, ta) = (
        bits(f.get(1), "detour start")?,
        bits(f.get(2), "detour duration")?,
        bits(f.get(3), "detour arrival")?,
    );
    let m: usize = f
        .get(4)
        .and_then(|v| v.parse().ok())
        .filter(|m| (2..=MAX_DETOUR).contains(m))
        .ok_or_else(|| anyhow!("a detour needs 2 to {MAX_DETOUR} postures"))?;
    if f.len() != 5 + 3 * m {
        bail!(
            "a detour of {m} postures has {} values, not {}",
            f.len() - 5,
            3 * m
        );
    }
    let mut pts = vec![[0.0; 3]; m];
    for (i, p) in pts.iter_mut().enumerate() {
        for (j, v) in p.iter_mut().enumerate() {
            *v = bits(f.get(5 + 3 * i + j), "detour posture")?;
        }
    }
    DetourTable::new(ts, dur, ta, &pts)
        .map(Some)
        .map_err(|e| anyhow!(e))
}

/// The handover [`line`] wrote (its fields after the tick number), for the planar arm
/// (`spatial` `None`) or a spatial one whose postures have `spatial` entries each
/// (`MAX_JOINTS`; 7 in recordings made before the capacity became 12).
pub fn parse(fields: &[&str], spatial: Option<usize>) -> Result<Option<Steering>> {
    match fields.first() {
        Some(&"0") if fields.len() == 1 => return Ok(None),
        Some(&"1") => {}
        _ => bail!("a steering record starts with 0 (none) or 1 (a cycle)"),
    }
    if let Some(width) = spatial {
        let (cycle, kp, kd, rest) = parse_cycle::<MAX_JOINTS>(&fields[1..], width)?;
        if !rest.is_empty() {
            bail!("a spatial robot's steering record ends after its postures");
        }
        return Ok(Some(Steering::Spatial(SpatialSteer { cycle, kp, kd })));
    }
    let (cycle, kp, kd, rest) = parse_cycle::<3>(&fields[1..], 3)?;
    Ok(Some(Steering::Planar(Steer {
        cycle,
        detour: detour(rest)?,
        kp,
        kd,
    })))
}

/// `t0 period kp kd k q…` of `w` entries a posture (at most `N`; the rest stay zero): the
/// table, the gains, and the fields after it.
fn parse_cycle<'a, 'b, const N: usize>(
    f: &'a [&'b str],
    w: usize,
) -> Result<(CycleTable<N>, f64, f64, &'a [&'b str])> {
    if w > N {
        bail!("a steering record of {w} joints where {N} fit");
    }
    let (t0, period) = (bits(f.first(), "t0")?, bits(f.get(1), "period")?);
    let (kp, kd) = (bits(f.get(2), "kp")?, bits(f.get(3), "kd")?);
    let k: usize = f
        .get(4)
        .and_then(|v| v.parse().ok())
        .filter(|k| (1..=MAX_PHASES).contains(k))
        .ok_or_else(|| anyhow!("a steering record needs 1 to {MAX_PHASES} postures"))?;
    if f.len() < 5 + w * k {
        bail!(
            "a steering record of {k} postures has {} values, not {}",
            f.len() - 5,
            w * k
        );
    }
    let mut rows = vec![[0.0; N]; k];
    for (i, row) in rows.iter_mut().enumerate() {
        for (j, v) in row[..w].iter_mut().enumerate() {
            *v = bits(f.get(5 + w * i + j), "posture")?;
        }
    }
    let cycle = CycleTable::from_rows(t0, period, &rows).map_err(|e| anyhow!(e))?;
    Ok((cycle, kp, kd, &f[5 + w * k..]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(s: Steering, spatial: Option<usize>) -> Vec<String> {
        let text = line(Some(&s));
        let fields: Vec<&str> = text.split(' ').collect();
        assert_eq!(parse(&fields, spatial).unwrap(), Some(s));
        assert!(parse(&fields[..fields.len() - 1], spatial).is_err());
        let mut bad = fields.clone();
        bad[3] = "zz";
        assert!(parse(&bad, spatial).is_err());
        fields.into_iter().map(String::from).collect()
    }

    #[test]
    fn a_handover_survives_its_line_bit_for_bit_and_damage_is_refused() {
        let rows = [[0.1, -2.0, 3.0e-9], [1.0 / 3.0, 0.0, -0.0]];
        let s = Steer::new(CycleTable::from_rows(0.25, 1.0, &rows).unwrap(), 1.0);
        round_trip(Steering::Planar(s), None);
        assert_eq!(parse(&["0"], None).unwrap(), None);
        assert!(parse(&["2"], None).is_err());
        // With a detour.
        let pts = [[0.1, 0.2, 0.3], [0.4, -0.5, 1.0 / 7.0], [1.0, 2.0, 3.0]];
        let d = DetourTable::new(0.5, 1.25, 2.0, &pts).unwrap();
        let s = Steer {
            detour: Some(d),
            ..s
        };
        let fields = round_trip(Steering::Planar(s), None);
        let mut bad: Vec<&str> = fields.iter().map(String::as_str).collect();
        let at = bad.iter().position(|f| *f == "D").unwrap();
        bad[at] = "E";
        assert!(parse(&bad, None).is_err());
    }

    #[test]
    fn a_spatial_handover_keeps_every_joint_and_takes_no_detour() {
        let rows: Vec<[f64; MAX_JOINTS]> = (0..5)
            .map(|k| std::array::from_fn(|i| (k * 7 + i) as f64 / 9.0 - 1.0))
            .collect();
        let s = SpatialSteer {
            cycle: CycleTable::from_rows(0.5, 2.0, &rows).unwrap(),
            kp: 39.47841760435743,
            kd: 12.566370614359172,
        };
        let fields = round_trip(Steering::Spatial(s), Some(MAX_JOINTS));
        assert_eq!(fields.len(), 6 + 5 * MAX_JOINTS);
        // Read as the planar arm's it is not the same handover.
        let f: Vec<&str> = fields.iter().map(String::as_str).collect();
        assert!(parse(&f, None).is_err());
        let mut longer = f.clone();
        longer.push("D");
        assert!(parse(&longer, Some(MAX_JOINTS))
            .unwrap_err()
            .to_string()
            .contains("ends after"));
    }

    /// A recording made when the capacity was 7 holds postures of 7 entries: they read into
    /// the wider table with the rest zero, and the same line read as 12-wide is refused.
    #[test]
    fn a_handover_of_seven_wide_postures_reads_into_the_wider_table() {
        let rows7: Vec<[f64; 7]> = (0..3)
            .map(|k| std::array::from_fn(|i| (k * 7 + i) as f64 / 9.0 - 1.0))
            .collect();
        let mut text = format!("1 {} {} {} {} 3", hex(0.5), hex(2.0), hex(40.0), hex(12.0));
        for v in rows7.iter().flatten() {
            text.push(' ');
            text.push_str(&hex(*v));
        }
        let f: Vec<&str> = text.split(' ').collect();
        let Some(Steering::Spatial(s)) = parse(&f, Some(7)).unwrap() else {
            panic!("not a spatial handover");
        };
        let wide: Vec<[f64; MAX_JOINTS]> = rows7
            .iter()
            .map(|r| std::array::from_fn(|i| r.get(i).copied().unwrap_or(0.0)))
            .collect();
        assert_eq!(s.cycle, CycleTable::from_rows(0.5, 2.0, &wide).unwrap());
        assert!(parse(&f, Some(MAX_JOINTS)).is_err());
    }
}
