//! Angles as the planner, the law and the analysis compare them: wrapped to one turn.

use std::f64::consts::{PI, TAU};

/// Wraps an angle difference into (−π, π].
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI {
        w - TAU
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_angle_is_into_the_half_open_interval() {
        for (a, w) in [
            (0.0, 0.0),
            (PI, PI),
            (-PI, PI),
            (3.0 * PI, PI),
            (TAU + 0.5, 0.5),
            (-0.5, -0.5),
        ] {
            assert!((wrap_angle(a) - w).abs() < 1e-12, "{a} → {}", wrap_angle(a));
        }
    }
}
