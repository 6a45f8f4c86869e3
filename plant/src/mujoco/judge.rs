//! MuJoCo as the judge of contact: its own collision detection over the model's geometry (the
//! robot's meshes, not chaosd's capsules) says whether a link touched an obstacle or the arm
//! itself, and its geom distance how close any link came.
//!
//! Pairs of the arm's bodies that already touch in the start pose are the model's own overlap
//! (a hand's fingers, meshes drawn into each other): [`super::load`] excludes them from contact,
//! and every other contact counts. Contacts are read once a period, after the period's steps; the smallest
//! distance every [`DISTANCE_EVERY`] periods (a few µs per geom pair).

use crate::report::ContactReport;
use mujoco_rs::mujoco_c::{mjData, mjModel, mj_geomDistance, mjtObj};

/// Periods between two distance sweeps.
pub const DISTANCE_EVERY: u64 = 10;
/// Farther than this (m), a distance is not worth knowing exactly.
const DISTANCE_MAX: f64 = 1.0;

pub struct Judge {
    /// Geoms on the arm's moving bodies.
    robot: Vec<usize>,
    obstacles: Vec<usize>,
    report: ContactReport,
    periods: u64,
    /// Obstacle slots in use (the first `active` of `obstacles`).
    active: usize,
    /// The first obstacle and own contact's geoms (named only in the report: no allocation on
    /// the loop).
    first: Option<(usize, usize)>,
    first_own: Option<(usize, usize)>,
}

impl Judge {
    /// Reads the geoms of `m`; `excluded` body pairs were taken out of contact.
    pub fn new(m: &mjModel, obstacles: Vec<usize>, excluded: usize) -> Self {
        let n = m.ngeom as usize;
        // SAFETY: geom_bodyid has ngeom entries.
        let body = unsafe { std::slice::from_raw_parts(m.geom_bodyid, n) };
        let robot: Vec<usize> = (0..n)
            .filter(|&g| body[g] > 0 && !obstacles.contains(&g))
            .collect();
        // (The obstacles sit on mocap bodies of their own, so `body > 0` alone would count them.)
        let mut j = Self {
            robot,
            obstacles,
            report: ContactReport::default(),
            periods: 0,
            active: 0,
            first: None,
            first_own: None,
        };
        j.report.robot_geoms = j.robot.len();
        j.report.judged = !j.robot.is_empty();
        j.report.overlapping_at_start = excluded;
        j
    }

    /// Reads this period's contacts (and now and then the distances) at plant time `t`.
    pub fn observe(&mut self, m: &mjModel, d: &mut mjData, t: f64) {
        self.periods += 1;
        let (mut obstacle, mut own) = (false, false);
        for (a, b) in contacts(d) {
            let (ra, rb) = (self.robot.contains(&a), self.robot.contains(&b));
            let (oa, ob) = (self.obstacles.contains(&a), self.obstacles.contains(&b));
            if (ra && ob) || (rb && oa) {
                obstacle = true;
                if self.first.is_none() {
                    self.report.first_contact_s = Some(t);
                    self.first = Some((a, b));
                }
            } else if ra && rb {
                own = true;
                if self.first_own.is_none() {
                    self.report.first_self_contact_s = Some(t);
                    self.first_own = Some((a, b));
                }
            }
        }
        self.report.obstacle_contact_periods += u64::from(obstacle);
        self.report.self_contact_periods += u64::from(own);
        if self.periods % DISTANCE_EVERY == 1 {
            self.sweep(m, d);
        }
    }

    /// How many obstacle slots are in use now.
    pub fn set_active(&mut self, n: usize) {
        self.active = n.min(self.obstacles.len());
        self.report.obstacles = self.active;
    }

    /// A live edit moved the spheres.
    pub fn scene_changed(&mut self) {
        self.report.scene_updates += 1;
    }

    /// The smallest signed distance between any arm geom and any obstacle in use.
    fn sweep(&mut self, m: &mjModel, d: &mut mjData) {
        for &o in &self.obstacles[..self.active] {
            for &g in &self.robot {
                // SAFETY: both ids are below ngeom; a null fromto is allowed.
                let dist = unsafe {
                    mj_geomDistance(m, d, g as i32, o as i32, DISTANCE_MAX, std::ptr::null_mut())
                };
                let best = self.report.smallest_distance_m.get_or_insert(dist);
                *best = best.min(dist);
            }
        }
    }

    /// What the start-up measured of the set-up's capsules against the model's geometry.
    pub fn set_outside_capsules(&mut self, outside: Option<(usize, f64)>) {
        self.report.outside_capsules = outside;
    }

    pub fn report(&self, m: &mjModel) -> ContactReport {
        let mut r = self.report.clone();
        r.first_pair = self.first.map(|(a, b)| pair_name(m, a, b));
        r.first_self_pair = self.first_own.map(|(a, b)| pair_name(m, a, b));
        r
    }
}

/// The geom pairs of the contacts MuJoCo found in its last collision pass.
fn contacts(d: &mjData) -> impl Iterator<Item = (usize, usize)> + '_ {
    let n = d.ncon.max(0) as usize;
    (0..n).map(move |i| {
        // SAFETY: `contact` holds ncon entries after a collision pass.
        let c = unsafe { &*d.contact.add(i) };
        (c.geom[0].max(0) as usize, c.geom[1].max(0) as usize)
    })
}

/// "link body / obstacle" for a report, by the bodies' and geoms' names.
fn pair_name(m: &mjModel, a: usize, b: usize) -> String {
    let name = |g: usize| {
        let own = super::load::name_of(m, mjtObj::mjOBJ_GEOM, g);
        if !own.is_empty() {
            return own;
        }
        // SAFETY: g < ngeom.
        let body = unsafe { *m.geom_bodyid.add(g) } as usize;
        super::load::name_of(m, mjtObj::mjOBJ_BODY, body)
    };
    format!("{} / {}", name(a), name(b))
}
