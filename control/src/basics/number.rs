//! How a number that moves on its own reads in a report, a log line or `chaosctl status`.
//!
//! A gain the daemon adapted (`mu = "auto"`), restored from a saved state or read back from
//! the status is a float with every digit it has (`0.11295023796157562`); what a person needs
//! is its size. The values a user typed print as typed, because `short` keeps them exact.

/// Three significant digits, trailing zeros dropped, so that 1.0 reads `1`, 0.2 `0.2` and
/// 0.112950237 `0.113`; beyond 0.001..1e6 in scientific notation.
///
/// ```
/// use control::basics::number::short;
/// assert_eq!(short(0.11295023796157562), "0.113");
/// assert_eq!(short(1.0), "1");
/// assert_eq!(short(0.2), "0.2");
/// assert_eq!(short(12.5), "12.5");
/// assert_eq!(short(2.5e-4), "2.50e-4");
/// assert_eq!(short(0.0), "0");
/// assert_eq!(short(-0.0456), "-0.0456");
/// ```
pub fn short(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    let magnitude = x.abs().log10().floor() as i32;
    if !(-3..6).contains(&magnitude) {
        return format!("{x:.2e}");
    }
    let decimals = (2 - magnitude).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}
