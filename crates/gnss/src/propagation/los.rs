//! Link geometry: is the straight segment between two points clear, through foliage, or
//! blocked by buildings, and by how much.
//!
//! Buildings and forests are vertical prisms: a simple polygon extruded between a lower and
//! an upper height. A prism occupies `lo ≤ z < hi` (half open at the top, so an antenna
//! standing exactly on a roof is outside the building under it), and its footprint is
//! closed (a segment touching a wall counts as hitting it).
//!
//! A segment test first clips the segment to the prism's height range, then tests the 2-D
//! projection of the clipped part against the footprint: it hits when an end lies inside
//! the footprint or the segment touches an edge. Lengths inside a prism come from the
//! sorted edge crossings, each interval between two crossings classified by its midpoint.
//!
//! **Symmetry.** [`Scene::segment_blocked`] orders the two end points lexicographically
//! before any arithmetic, so `blocked(a, b)` and `blocked(b, a)` run the very same floating
//! point operations and agree exactly, grazing cases included (a property test checks it).

use super::index::Aabb;
use super::scene::{WallMaterial, MAX_POLYGON_VERTICES};
use super::Scene;
use nalgebra::Vector3;

/// One prism: a polygon (a range of the shared vertex list) between two heights.
#[derive(Clone, Debug)]
pub(crate) struct Prism {
    pub first: u32,
    pub len: u32,
    pub lo_m: f64,
    pub hi_m: f64,
}

/// A set of prisms with their shared vertex list and their hierarchy.
#[derive(Clone, Debug, Default)]
pub(crate) struct PrismSet {
    pub verts: Vec<[f64; 2]>,
    pub prisms: Vec<Prism>,
    pub bvh: super::index::Bvh,
}

impl PrismSet {
    /// Builds the set; polygons must be validated and counter-clockwise.
    pub fn new(items: impl Iterator<Item = (Vec<[f64; 2]>, f64, f64)>) -> Self {
        let mut verts = Vec::new();
        let mut prisms = Vec::new();
        let mut boxes = Vec::new();
        for (poly, lo_m, hi_m) in items {
            let mut b = Aabb::EMPTY;
            for p in &poly {
                b = b.union(&Aabb {
                    min: [p[0], p[1], lo_m],
                    max: [p[0], p[1], hi_m],
                });
            }
            prisms.push(Prism {
                first: verts.len() as u32,
                len: poly.len() as u32,
                lo_m,
                hi_m,
            });
            verts.extend_from_slice(&poly);
            boxes.push(b);
        }
        let bvh = super::index::Bvh::build(&boxes);
        Self { verts, prisms, bvh }
    }

    pub fn poly(&self, i: u32) -> &[[f64; 2]] {
        let p = &self.prisms[i as usize];
        &self.verts[p.first as usize..(p.first + p.len) as usize]
    }

    /// The first prism containing `p`, if any.
    pub fn containing(&self, p: [f64; 3]) -> Option<u32> {
        let q = Aabb { min: p, max: p };
        let mut found = None;
        self.bvh.overlapping(&q, |i| {
            let pr = &self.prisms[i as usize];
            if p[2] >= pr.lo_m && p[2] < pr.hi_m && point_in_polygon(self.poly(i), [p[0], p[1]]) {
                found = Some(i);
                true
            } else {
                false
            }
        });
        found
    }

    /// The segment's parameter range inside prism `i`'s height band, `t0 < t1` (or the
    /// whole segment for a horizontal one inside the band).
    fn z_clip(&self, i: u32, a: &[f64; 3], b: &[f64; 3]) -> Option<(f64, f64)> {
        let pr = &self.prisms[i as usize];
        let dz = b[2] - a[2];
        if dz == 0.0 {
            return (a[2] >= pr.lo_m && a[2] < pr.hi_m).then_some((0.0, 1.0));
        }
        let ta = (pr.lo_m - a[2]) / dz;
        let tb = (pr.hi_m - a[2]) / dz;
        let t0 = ta.min(tb).max(0.0);
        let t1 = ta.max(tb).min(1.0);
        // A segment that only grazes the roof or floor plane at one point does not enter.
        (t0 < t1).then_some((t0, t1))
    }

    /// Whether the segment from `a` to `b` touches prism `i`.
    pub fn segment_hits(&self, i: u32, a: &[f64; 3], b: &[f64; 3]) -> bool {
        let Some((t0, t1)) = self.z_clip(i, a, b) else {
            return false;
        };
        let p0 = [a[0] + t0 * (b[0] - a[0]), a[1] + t0 * (b[1] - a[1])];
        let p1 = [a[0] + t1 * (b[0] - a[0]), a[1] + t1 * (b[1] - a[1])];
        let poly = self.poly(i);
        if point_in_polygon(poly, p0) {
            return true;
        }
        let n = poly.len();
        (0..n).any(|k| super::scene::segments_touch(p0, p1, poly[k], poly[(k + 1) % n]))
    }

    /// The length (m) of the segment `a → b` inside prism `i`, and the number of times it
    /// passes through the prism's surface strictly between its ends (walls, roof or floor).
    pub fn inside(&self, i: u32, a: &[f64; 3], b: &[f64; 3]) -> (f64, u32) {
        let Some((t0, t1)) = self.z_clip(i, a, b) else {
            return (0.0, 0);
        };
        let p0 = [a[0] + t0 * (b[0] - a[0]), a[1] + t0 * (b[1] - a[1])];
        let p1 = [a[0] + t1 * (b[0] - a[0]), a[1] + t1 * (b[1] - a[1])];
        let poly = self.poly(i);
        let n = poly.len();
        // Edge crossings as parameters s ∈ (0, 1) of the clipped 2-D segment.
        let mut cuts = [0.0f64; MAX_POLYGON_VERTICES + 2];
        let mut m = 0usize;
        cuts[m] = 0.0;
        m += 1;
        let d = [p1[0] - p0[0], p1[1] - p0[1]];
        if d[0] != 0.0 || d[1] != 0.0 {
            for k in 0..n {
                let (e0, e1) = (poly[k], poly[(k + 1) % n]);
                let e = [e1[0] - e0[0], e1[1] - e0[1]];
                let den = d[0] * e[1] - d[1] * e[0];
                if den == 0.0 {
                    // Parallel: a collinear overlap adds no crossing; the midpoint test
                    // of the neighbouring intervals classifies it.
                    continue;
                }
                let w = [e0[0] - p0[0], e0[1] - p0[1]];
                let s = (w[0] * e[1] - w[1] * e[0]) / den;
                let u = (w[0] * d[1] - w[1] * d[0]) / den;
                if s > 0.0 && s < 1.0 && (0.0..=1.0).contains(&u) {
                    cuts[m] = s;
                    m += 1;
                }
            }
        }
        cuts[m] = 1.0;
        m += 1;
        cuts[1..m - 1].sort_unstable_by(f64::total_cmp);
        let seg_len =
            ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
        let mut frac = 0.0;
        let mut surfaces = 0u32;
        let mut prev_inside: Option<bool> = None;
        let mut first_inside = false;
        for k in 0..m - 1 {
            let (s0, s1) = (cuts[k], cuts[k + 1]);
            if s1 <= s0 {
                continue;
            }
            let sm = 0.5 * (s0 + s1);
            let inside = point_in_polygon(poly, [p0[0] + sm * d[0], p0[1] + sm * d[1]]);
            if inside {
                frac += s1 - s0;
            }
            match prev_inside {
                None => first_inside = inside,
                Some(p) if p != inside => surfaces += 1,
                _ => {}
            }
            prev_inside = Some(inside);
        }
        let last_inside = prev_inside.unwrap_or(false);
        // Entering or leaving through the roof or the floor is a surface crossing too,
        // unless it happens at the segment's own end.
        if first_inside && t0 > 0.0 {
            surfaces += 1;
        }
        if last_inside && t1 < 1.0 {
            surfaces += 1;
        }
        (frac * (t1 - t0) * seg_len, surfaces)
    }
}

/// Crossing-number point-in-polygon test (half-open rule, so a point on a shared edge
/// belongs to exactly one of two adjacent polygons).
pub(crate) fn point_in_polygon(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = poly.len();
    let mut inside = false;
    let mut j = n - 1;
    for i in 0..n {
        let (vi, vj) = (poly[i], poly[j]);
        if (vi[1] > p[1]) != (vj[1] > p[1]) {
            let x = (vj[0] - vi[0]) * (p[1] - vi[1]) / (vj[1] - vi[1]) + vi[0];
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

/// What a segment passes through.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Obstruction {
    /// Building surfaces crossed (walls, roofs), counted per [`WallMaterial::index`].
    pub walls_by_material: [u32; 6],
    /// Length inside buildings (m).
    pub building_path_m: f64,
    /// Length inside foliage (m).
    pub foliage_path_m: f64,
    /// Σ density·length over the forests crossed (m): the foliage length weighted by each
    /// forest's `foliage_density`, which is what the vegetation loss uses.
    pub foliage_weighted_m: f64,
}

impl Obstruction {
    /// The total number of building surfaces crossed.
    pub fn walls(&self) -> u32 {
        self.walls_by_material.iter().sum()
    }

    /// Whether the segment passes through a building: a surface crossing or a length
    /// inside. A segment that only grazes a wall or an edge (zero length inside) counts as
    /// clear here but as blocked by [`Scene::segment_blocked`], whose closed test is the
    /// conservative one used for reflection legs.
    pub fn blocked(&self) -> bool {
        self.walls() > 0 || self.building_path_m > 0.0
    }

    /// The classification of [`LosState`].
    pub fn state(&self) -> LosState {
        if self.blocked() {
            LosState::Blocked {
                walls: self.walls(),
                foliage_path_m: self.foliage_path_m,
            }
        } else if self.foliage_path_m > 0.0 {
            LosState::Foliage {
                path_m: self.foliage_path_m,
            }
        } else {
            LosState::Clear
        }
    }

    /// The sum of the wall penetration losses at `freq_hz` (dB), see
    /// [`WallMaterial::penetration_loss_db`].
    pub fn wall_loss_db(&self, freq_hz: f64) -> f64 {
        WallMaterial::ALL
            .iter()
            .map(|m| f64::from(self.walls_by_material[m.index()]) * m.penetration_loss_db(freq_hz))
            .sum()
    }
}

/// The line-of-sight state of a link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LosState {
    /// Nothing in the way.
    Clear,
    /// Only foliage in the way, over `path_m` metres.
    Foliage { path_m: f64 },
    /// One or more buildings in the way: `walls` surfaces crossed, plus any foliage.
    Blocked { walls: u32, foliage_path_m: f64 },
}

fn arr(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Orders two points lexicographically, so that a symmetric predicate computes the same
/// arithmetic whichever way round it is asked.
fn canonical(a: [f64; 3], b: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let ord = a[0]
        .total_cmp(&b[0])
        .then(a[1].total_cmp(&b[1]))
        .then(a[2].total_cmp(&b[2]));
    if ord.is_gt() {
        (b, a)
    } else {
        (a, b)
    }
}

impl Scene {
    /// Whether the segment `a → b` touches any building other than those in `skip`
    /// (pass `[None, None]` to skip none). Stops at the first hit.
    pub fn segment_blocked_except(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        skip: [Option<u32>; 2],
    ) -> bool {
        let (a, b) = canonical(arr(a), arr(b));
        let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let bs = &self.buildings;
        bs.bvh.segment(a, d, |i| {
            Some(i) != skip[0] && Some(i) != skip[1] && bs.segment_hits(i, &a, &b)
        })
    }

    /// Whether the segment `a → b` touches any building. Symmetric in `a` and `b`, exactly.
    pub fn segment_blocked(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
        self.segment_blocked_except(a, b, [None, None])
    }

    /// Everything the segment `a → b` passes through, buildings in `skip` excepted.
    pub fn obstruction(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        skip: [Option<u32>; 2],
    ) -> Obstruction {
        let (a, b) = canonical(arr(a), arr(b));
        let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let mut o = Obstruction::default();
        let bs = &self.buildings;
        bs.bvh.segment(a, d, |i| {
            if Some(i) != skip[0] && Some(i) != skip[1] {
                let (len, walls) = bs.inside(i, &a, &b);
                let mat = self.materials[i as usize].index();
                o.walls_by_material[mat] += walls;
                o.building_path_m += len;
            }
            false
        });
        let fs = &self.forests;
        fs.bvh.segment(a, d, |i| {
            let (len, _) = fs.inside(i, &a, &b);
            o.foliage_path_m += len;
            o.foliage_weighted_m += len * self.foliage_density[i as usize];
            false
        });
        o
    }

    /// The far end of the segment that represents a link to `tx` from `rx`: the point
    /// itself, or for a direction, the point where the ray from `rx` leaves the box around
    /// every building and forest (plus 1 m), beyond which nothing can obstruct it.
    pub fn far_end(&self, rx: &Vector3<f64>, tx: &super::Emitter) -> Vector3<f64> {
        match tx {
            super::Emitter::Point(p) => *p,
            super::Emitter::Direction(u) => {
                let b = self.bounds;
                let t = b.clip(arr(rx), arr(u), 1.0e9).map_or(0.0, |(_, t1)| t1);
                rx + u * (t + 1.0)
            }
        }
    }
}
