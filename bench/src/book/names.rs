//! Every table the bench can write into the book, under the name its marker carries
//! (`<!-- bench:NAME -->`), and the page that carries it. A leaf: the chapter test
//! (`bench/tests/book.rs`) includes this file as it is, so the bench and the book cannot drift
//! apart unnoticed.

/// One table: its marker name, and the book page that carries it (a file under `docs/`), if
/// any does. A name starts with the part that writes it.
#[derive(Clone, Copy, Debug)]
pub struct Entry {
    pub name: &'static str,
    pub page: Option<&'static str>,
}

/// The performance chapter.
pub const PERFORMANCE: &str = "performance.md";

pub const LATENCY: &str = "latency";
/// `latency --pace-us P`: the round trips paced at a loop's rate, not back to back.
pub const LATENCY_PACED: &str = "latency-paced";
pub const JITTER: &str = "jitter";
pub const E2E: &str = "e2e";
pub const E2E_MODES: &str = "e2e-modes";
pub const E2E_LATE: &str = "e2e-late";
pub const E2E_REQUESTS: &str = "e2e-requests";
pub const E2E_MONITOR: &str = "e2e-monitor";
pub const E2E_VIEWER: &str = "e2e-viewer";
pub const COMPUTE: &str = "compute";
pub const COMPUTE_TICK: &str = "compute-tick";
pub const COMPUTE_MONITOR: &str = "compute-monitor";
pub const COMPUTE_RECORD: &str = "compute-record";
pub const COMPUTE_PANDA: &str = "compute-panda";
pub const COMPUTE_COMMANDS: &str = "compute-commands";
pub const COMPUTE_COMMANDS_COST: &str = "compute-commands-cost";
pub const COMPUTE_PLAN: &str = "compute-plan";
pub const COMPUTE_PLAN_PANDA: &str = "compute-plan-panda";
pub const COMPUTE_MODEL: &str = "compute-model";
pub const DEVICE: &str = "device";
pub const PLANTS: &str = "plants";
pub const SOAK_FAULTS: &str = "soak-faults";
pub const SOAK_PROCESSES: &str = "soak-processes";
pub const SOAK_DATA: &str = "soak-data";

const fn e(name: &'static str, page: Option<&'static str>) -> Entry {
    Entry { name, page }
}

/// The catalogue, in the order the parts print their tables.
pub const ALL: &[Entry] = &[
    e(LATENCY, Some(PERFORMANCE)),
    e(LATENCY_PACED, None),
    e(JITTER, Some(PERFORMANCE)),
    e(E2E, Some(PERFORMANCE)),
    e(E2E_MODES, None),
    e(E2E_LATE, None),
    e(E2E_REQUESTS, Some(PERFORMANCE)),
    e(E2E_MONITOR, None),
    e(E2E_VIEWER, None),
    e(COMPUTE, Some(PERFORMANCE)),
    e(COMPUTE_TICK, None),
    e(COMPUTE_MONITOR, None),
    e(COMPUTE_RECORD, None),
    e(COMPUTE_PANDA, None),
    e(COMPUTE_COMMANDS, None),
    e(COMPUTE_COMMANDS_COST, None),
    e(COMPUTE_PLAN, None),
    e(COMPUTE_PLAN_PANDA, None),
    e(COMPUTE_MODEL, None),
    e(DEVICE, None),
    e(PLANTS, Some(PERFORMANCE)),
    e(SOAK_FAULTS, None),
    e(SOAK_PROCESSES, None),
    e(SOAK_DATA, None),
];

/// Whether the bench writes a table of this name.
pub fn known(name: &str) -> bool {
    ALL.iter().any(|t| t.name == name)
}

/// The tables a book page must carry.
pub fn carried_by(page: &str) -> impl Iterator<Item = &'static Entry> + '_ {
    ALL.iter().filter(move |t| t.page == Some(page))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_fit_a_marker() {
        for (i, t) in ALL.iter().enumerate() {
            assert!(
                !t.name.is_empty()
                    && t.name
                        .bytes()
                        .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-'),
                "{}",
                t.name
            );
            assert!(
                ALL[..i].iter().all(|u| u.name != t.name),
                "{} twice",
                t.name
            );
        }
        assert!(known(E2E_REQUESTS) && !known("e2e-request"));
        assert_eq!(carried_by(PERFORMANCE).count(), 6);
    }
}
