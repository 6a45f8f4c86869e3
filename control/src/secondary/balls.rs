//! Obstacles as balls: a disc in the planar arm's plane, a sphere in space. One type for every
//! arm, generic in the dimension `D`, so the potential, the barrier rows, the daemon's edits
//! and the planners read one list whatever the arm; stored inline, so a parameter block that
//! holds them stays `Copy` and reaches the real-time loop without allocating.

use nalgebra::SVector;

/// The most obstacles one parameter block holds.
pub const MAX_OBSTACLES: usize = 16;

/// A ball obstacle: centre c, radius r and the margin s at which its potential starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball<const D: usize> {
    pub center: SVector<f64, D>,
    pub radius: f64,
    pub margin: f64,
}

impl<const D: usize> Default for Ball<D> {
    fn default() -> Self {
        Self {
            center: SVector::zeros(),
            radius: 0.0,
            margin: 0.0,
        }
    }
}

/// Up to [`MAX_OBSTACLES`] balls, stored inline.
///
/// ```
/// use control::secondary::{Ball, Balls};
/// use nalgebra::Vector2;
///
/// let mut set = Balls::<2>::new();
/// let disc = Ball { center: Vector2::new(1.0, 1.6), radius: 0.2, margin: 0.1 };
/// assert_eq!(set.push(disc), Ok(0));
/// assert_eq!(set.remove(0), Some(disc));
/// assert!(set.is_empty());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Balls<const D: usize> {
    items: [Ball<D>; MAX_OBSTACLES],
    len: usize,
}

impl<const D: usize> Default for Balls<D> {
    fn default() -> Self {
        Self {
            items: [Ball::default(); MAX_OBSTACLES],
            len: 0,
        }
    }
}

/// A set already holds [`MAX_OBSTACLES`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("at most {MAX_OBSTACLES} obstacles are supported")]
pub struct ObstaclesFull;

impl<const D: usize> Balls<D> {
    pub fn new() -> Self {
        Self::default()
    }
    /// Adds a ball; its index, or [`ObstaclesFull`].
    pub fn push(&mut self, o: Ball<D>) -> Result<usize, ObstaclesFull> {
        if self.len == MAX_OBSTACLES {
            return Err(ObstaclesFull);
        }
        self.items[self.len] = o;
        self.len += 1;
        Ok(self.len - 1)
    }
    /// Removes ball `i`, keeping the order of the rest.
    pub fn remove(&mut self, i: usize) -> Option<Ball<D>> {
        if i >= self.len {
            return None;
        }
        let o = self.items[i];
        self.items.copy_within(i + 1..self.len, i);
        self.len -= 1;
        Some(o)
    }
    pub fn as_slice(&self) -> &[Ball<D>] {
        &self.items[..self.len]
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl<const D: usize> FromIterator<Ball<D>> for Balls<D> {
    /// Collects up to [`MAX_OBSTACLES`]; callers validate the count first.
    fn from_iter<I: IntoIterator<Item = Ball<D>>>(iter: I) -> Self {
        let mut s = Self::new();
        for o in iter.into_iter().take(MAX_OBSTACLES) {
            let _ = s.push(o);
        }
        s
    }
}

/// Smallest distance from a ball's surface to a link's surface (negative: penetration), and
/// whether any link is inside a ball's zone r + margin. Link j of `links` runs between the two
/// points `ends(j)`, a capsule of radius `link_radii[j]` (0: a segment).
pub fn clearance<const D: usize>(
    balls: &Balls<D>,
    links: usize,
    ends: impl Fn(usize) -> (SVector<f64, D>, SVector<f64, D>),
    link_radii: &[f64],
) -> (f64, bool) {
    let mut min = f64::INFINITY;
    let mut in_zone = false;
    for o in balls.as_slice() {
        for j in 0..links {
            let (a, b) = ends(j);
            let d = b - a;
            let l2 = d.norm_squared();
            let t = if l2 > 0.0 {
                ((o.center - a).dot(&d) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let dist = (a + d * t - o.center).norm() - link_radii[j];
            min = min.min(dist - o.radius);
            in_zone |= dist < o.radius + o.margin;
        }
    }
    (min, in_zone)
}
