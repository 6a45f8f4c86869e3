//! The joint counts chaosd is built for, and the one place a runtime count becomes a type.
//!
//! Every fixed-size matrix in the crate is sized by these; they sit on the ground floor so that
//! a model, a filter and a config can all name them without importing one another.

/// Largest supported arm (also the size of the wire samples' arrays).
pub const MAX_JOINTS: usize = 12;
/// Smallest supported arm.
pub const MIN_JOINTS: usize = 2;

/// Runs `$body` with `$N` bound to the arm size `$n` as a const generic (2 ..= MAX_JOINTS).
///
/// The math is monomorphised per arm size so every matrix has a fixed size; this is the one place
/// a runtime size becomes a type.
#[macro_export]
macro_rules! with_dof {
    ($n:expr, $N:ident => $body:expr) => {
        match $n {
            2 => {
                const $N: usize = 2;
                $body
            }
            3 => {
                const $N: usize = 3;
                $body
            }
            4 => {
                const $N: usize = 4;
                $body
            }
            5 => {
                const $N: usize = 5;
                $body
            }
            6 => {
                const $N: usize = 6;
                $body
            }
            7 => {
                const $N: usize = 7;
                $body
            }
            8 => {
                const $N: usize = 8;
                $body
            }
            9 => {
                const $N: usize = 9;
                $body
            }
            10 => {
                const $N: usize = 10;
                $body
            }
            11 => {
                const $N: usize = 11;
                $body
            }
            12 => {
                const $N: usize = 12;
                $body
            }
            other => panic!("unsupported arm size {other}: validate the config first"),
        }
    };
}
