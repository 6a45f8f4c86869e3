//! Property tests for what arrives over shared memory: any bytes in a sample or a request are
//! checked without a panic, and a sample that passes `validate` holds only finite numbers in
//! its used entries.

use proptest::prelude::*;
use protocol::{CommandSample, ControlRequest, StateSample};

/// A value of a plain-data wire type made from arbitrary bytes. Every field of these types is an
/// integer, a float or an array of them, so every bit pattern is a valid value.
fn from_bytes<T: Copy>(bytes: &[u8]) -> T {
    assert_eq!(bytes.len(), std::mem::size_of::<T>());
    // SAFETY: the length matches and T is plain data (see above); read_unaligned copies.
    unsafe { std::ptr::read_unaligned(bytes.as_ptr() as *const T) }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5000))]

    #[test]
    fn any_state_bytes_are_checked_without_panic(
        bytes in prop::collection::vec(any::<u8>(), std::mem::size_of::<StateSample>()),
        n in 0usize..9,
    ) {
        let s: StateSample = from_bytes(&bytes);
        if s.validate(n).is_ok() {
            prop_assert!(s.phi.is_finite());
            prop_assert!(s.used_q().iter().chain(s.used_qd()).all(|v| v.is_finite()));
            prop_assert_eq!(s.n as usize, n);
        }
    }

    #[test]
    fn any_command_bytes_are_checked_without_panic(
        bytes in prop::collection::vec(any::<u8>(), std::mem::size_of::<CommandSample>()),
        n in 0usize..9,
    ) {
        let c: CommandSample = from_bytes(&bytes);
        if c.validate(n).is_ok() {
            prop_assert!(c.used_qdd().iter().all(|v| v.is_finite()));
            prop_assert!(c.mode().is_ok());
        }
    }

    #[test]
    fn any_request_bytes_are_read_without_panic(
        bytes in prop::collection::vec(any::<u8>(), std::mem::size_of::<ControlRequest>()),
    ) {
        let r: ControlRequest = from_bytes(&bytes);
        let _ = r.op();
        if let Ok(a) = r.args() {
            prop_assert!(a.len() <= protocol::control::MAX_ARGS);
        }
    }
}
