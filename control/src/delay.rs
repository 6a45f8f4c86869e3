//! The delay line behind the Pyragas term: q̇ on a uniform time grid, read back by linear
//! interpolation (docs/science.md, "Time, integration and determinism").
//!
//! Its capacity is fixed once from the largest delay the run may ask for, so pushing and reading
//! never allocate. Times are given in grid steps (`t / dt`) so that a delay that is a whole number of
//! steps reads stored samples exactly, with no rounding from dividing seconds by dt.

use crate::arm::VecN;

#[derive(Clone, Debug)]
pub struct DelayLine<const N: usize> {
    buf: Vec<VecN<N>>,
    /// Number of samples pushed so far; the newest has grid index `pushed - 1`.
    pushed: u64,
    /// History before the first sample (q̇(0) by convention).
    initial: VecN<N>,
}

impl<const N: usize> DelayLine<N> {
    /// A line that can look back at least `max_delay_steps` grid steps.
    pub fn new(max_delay_steps: f64, initial: VecN<N>) -> Self {
        let cap = max_delay_steps.max(1.0).ceil() as usize + 2;
        Self {
            buf: vec![initial; cap],
            pushed: 0,
            initial,
        }
    }

    /// How many steps back the line can reach.
    pub fn max_delay_steps(&self) -> f64 {
        (self.buf.len() - 2) as f64
    }

    /// Forgets every sample and restarts the history at `initial`.
    pub fn reset(&mut self, initial: VecN<N>) {
        self.pushed = 0;
        self.initial = initial;
    }

    /// Appends the sample for the next grid time.
    #[inline]
    pub fn push(&mut self, v: VecN<N>) {
        let cap = self.buf.len() as u64;
        self.buf[(self.pushed % cap) as usize] = v;
        self.pushed += 1;
    }

    /// The slot the next [`Self::push`] overwrites (the oldest sample, or the initial fill).
    /// A caller that waits between pushes reads it to bring that cache line back beforehand.
    #[inline]
    pub fn next_slot(&self) -> VecN<N> {
        self.buf[(self.pushed % self.buf.len() as u64) as usize]
    }

    /// Number of samples pushed so far.
    pub fn len(&self) -> u64 {
        self.pushed
    }

    pub fn is_empty(&self) -> bool {
        self.pushed == 0
    }

    #[inline]
    fn at_index(&self, i: i64) -> VecN<N> {
        if i < 0 || self.pushed == 0 {
            return self.initial;
        }
        let newest = self.pushed as i64 - 1;
        let oldest = (self.pushed as i64 - self.buf.len() as i64).max(0);
        let i = i.clamp(oldest, newest);
        self.buf[(i as u64 % self.buf.len() as u64) as usize]
    }

    /// The signal at grid time `x` (in steps), linearly interpolated. Before grid time 0 it is the
    /// initial history; past the newest sample it holds the newest.
    #[inline]
    pub fn sample(&self, x: f64) -> VecN<N> {
        let f = x.floor();
        let i = f as i64;
        let frac = x - f;
        let a = self.at_index(i);
        if frac == 0.0 {
            return a;
        }
        let b = self.at_index(i + 1);
        a + (b - a) * frac
    }

    /// The stored sample of grid index `index`, or None when it is not held (not pushed yet, or
    /// already overwritten): the delay system's state coordinates, for a linearisation that
    /// perturbs them one by one (`analysis::floquet`).
    pub fn stored_mut(&mut self, index: u64) -> Option<&mut VecN<N>> {
        let cap = self.buf.len() as u64;
        let held = index < self.pushed && index + cap >= self.pushed;
        held.then(|| &mut self.buf[(index % cap) as usize])
    }

    /// The stored sample of grid index `index`, when held (see [`Self::stored_mut`]).
    pub fn stored(&self, index: u64) -> Option<VecN<N>> {
        let cap = self.buf.len() as u64;
        let held = index < self.pushed && index + cap >= self.pushed;
        held.then(|| self.buf[(index % cap) as usize])
    }

    /// Stored samples from oldest to newest (mutable), with the initial history: the delay
    /// system's state segment, which a Lyapunov pair perturbs and renormalises.
    pub fn history_mut(&mut self) -> (&mut [VecN<N>], &mut VecN<N>) {
        (&mut self.buf[..], &mut self.initial)
    }

    /// Number of buffer slots currently holding real samples.
    pub fn filled(&self) -> usize {
        (self.pushed as usize).min(self.buf.len())
    }

    /// Storage slots, in buffer order (the order is irrelevant to norms and scalings).
    pub fn slots(&self) -> &[VecN<N>] {
        &self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    #[test]
    fn interpolates_linear_signals_exactly() {
        let f = |x: f64| Vector2::new(2.0 * x + 1.0, -0.5 * x);
        let mut d = DelayLine::<2>::new(50.0, f(0.0));
        for k in 0..200 {
            d.push(f(k as f64));
            for &back in &[0.0, 0.5, 1.0, 12.25, 49.75] {
                let x = k as f64 - back;
                let want = if x < 0.0 { f(0.0) } else { f(x) };
                assert!((d.sample(x) - want).norm() < 1e-12, "k={k} back={back}");
            }
        }
    }

    #[test]
    fn before_time_zero_holds_initial() {
        let mut d = DelayLine::<1>::new(10.0, nalgebra::Vector1::new(3.0));
        d.push(nalgebra::Vector1::new(3.0));
        d.push(nalgebra::Vector1::new(5.0));
        assert_eq!(d.sample(-4.5)[0], 3.0);
        assert_eq!(d.sample(0.5)[0], 4.0);
        assert_eq!(d.sample(7.0)[0], 5.0); // clamps to newest
    }
}
