//! A steering handover as one line of a replay recording, and back, bit for bit.

use anyhow::{anyhow, bail, Result};
use control::steer::detour::MAX_DETOUR;
use control::steer::CycleTable;
use control::steer::DetourTable;
use control::steer::Steer;
use control::steer::MAX_PHASES;

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

/// `0`, or `1 t0 period kp kd k q…` (every f64 as its bits).
pub fn line(steer: Option<&Steer>) -> String {
    let Some(s) = steer else {
        return "0".into();
    };
    let rows = s.cycle.rows();
    let mut out = format!(
        "1 {} {} {} {} {}",
        hex(s.cycle.t0),
        hex(s.cycle.period),
        hex(s.kp),
        hex(s.kd),
        rows.len()
    );
    for q in rows.iter().flatten() {
        out.push(' ');
        out.push_str(&hex(*q));
    }
    if let Some(d) = &s.detour {
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
    out
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

/// The handover [`line`] wrote (its fields after the tick number).
pub fn parse(fields: &[&str]) -> Result<Option<Steer>> {
    match fields.first() {
        Some(&"0") if fields.len() == 1 => return Ok(None),
        Some(&"1") => {}
        _ => bail!("a steering record starts with 0 (none) or 1 (a cycle)"),
    }
    let f = &fields[1..];
    let (t0, period) = (bits(f.first(), "t0")?, bits(f.get(1), "period")?);
    let (kp, kd) = (bits(f.get(2), "kp")?, bits(f.get(3), "kd")?);
    let k: usize = f
        .get(4)
        .and_then(|v| v.parse().ok())
        .filter(|k| (1..=MAX_PHASES).contains(k))
        .ok_or_else(|| anyhow!("a steering record needs 1 to {MAX_PHASES} postures"))?;
    if f.len() < 5 + 3 * k {
        bail!(
            "a steering record of {k} postures has {} values, not {}",
            f.len() - 5,
            3 * k
        );
    }
    let mut rows = vec![[0.0; 3]; k];
    for (i, row) in rows.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = bits(f.get(5 + 3 * i + j), "posture")?;
        }
    }
    let cycle = CycleTable::from_rows(t0, period, &rows).map_err(|e| anyhow!(e))?;
    let detour = detour(&f[5 + 3 * k..])?;
    Ok(Some(Steer {
        cycle,
        detour,
        kp,
        kd,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_handover_survives_its_line_bit_for_bit_and_damage_is_refused() {
        let rows = [[0.1, -2.0, 3.0e-9], [1.0 / 3.0, 0.0, -0.0]];
        let s = Steer::new(CycleTable::from_rows(0.25, 1.0, &rows).unwrap(), 1.0);
        let text = line(Some(&s));
        let fields: Vec<&str> = text.split(' ').collect();
        assert_eq!(parse(&fields).unwrap(), Some(s));
        assert_eq!(parse(&["0"]).unwrap(), None);
        assert!(parse(&fields[..fields.len() - 1]).is_err());
        assert!(parse(&["2"]).is_err());
        let mut bad = fields.clone();
        bad[3] = "zz";
        assert!(parse(&bad).is_err());
        // With a detour.
        let pts = [[0.1, 0.2, 0.3], [0.4, -0.5, 1.0 / 7.0], [1.0, 2.0, 3.0]];
        let d = DetourTable::new(0.5, 1.25, 2.0, &pts).unwrap();
        let s = Steer {
            detour: Some(d),
            ..s
        };
        let text = line(Some(&s));
        let fields: Vec<&str> = text.split(' ').collect();
        assert_eq!(parse(&fields).unwrap(), Some(s));
        assert!(parse(&fields[..fields.len() - 1]).is_err());
        let mut bad = fields.clone();
        let at = bad.iter().position(|f| *f == "D").unwrap();
        bad[at] = "E";
        assert!(parse(&bad).is_err());
    }
}
