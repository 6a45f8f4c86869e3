//! Posting news is what a loop may do: no allocation (the courier's logging may allocate, on
//! its own thread).

use rt::alloc_count::{allocations, Counting};
use rt::news::{Courier, Note};

#[global_allocator]
static A: Counting = Counting;

#[derive(Clone, Copy)]
struct Lost(u64);
impl Note for Lost {
    fn log(&self) {
        tracing::warn!("lost for {} ms", self.0);
    }
}

#[test]
fn posting_allocates_nothing_even_when_the_queue_is_full() {
    assert!(
        allocations(|| drop(std::hint::black_box(Box::new(7u64)))) >= 1,
        "the counter counts"
    );
    let courier = Courier::<Lost>::start("test-news", 4, None).unwrap();
    let p = courier.poster();
    let n = allocations(|| {
        for i in 0..16 {
            p.post(Lost(i));
        }
    });
    assert_eq!(n, 0);
    assert!(
        p.dropped() > 0,
        "the queue overflowed, so the full path ran too"
    );
}
