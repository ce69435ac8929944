//! A bounding-volume hierarchy over axis-aligned 3-D boxes, so that a segment or a box query
//! visits O(log n) nodes plus the primitives it really comes near.
//!
//! Why a BVH and not a uniform grid: building heights vary, and most rays of interest leave
//! the city through the roofs (a satellite above 15°) or fly above it (a broadcast mast)
//! for most of their length. Boxes that carry the roof height let such a ray skip whole
//! districts, where a 2-D grid would walk every cell under it.
//!
//! Construction: top-down median split on the longest axis of the centroids' bounds, leaves
//! of at most [`LEAF_SIZE`] primitives, nodes in one flat vector (depth-first order, the
//! right child's index stored in the node). Traversal uses a fixed-size stack on the call
//! stack, so queries never allocate.

/// The most primitives a leaf holds.
pub const LEAF_SIZE: usize = 4;
/// Traversal stack depth. A median split halves the primitive count at each level, so the
/// depth is ⌈log2(n / LEAF_SIZE)⌉ + 1: 64 covers any count a `u32` index can hold.
const STACK: usize = 64;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner (east, north, up), m.
    pub min: [f64; 3],
    /// Maximum corner, m.
    pub max: [f64; 3],
}

impl Aabb {
    /// The empty box (the identity of [`Aabb::union`]).
    pub const EMPTY: Aabb = Aabb {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };

    /// The smallest box holding both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: [
                self.min[0].min(o.min[0]),
                self.min[1].min(o.min[1]),
                self.min[2].min(o.min[2]),
            ],
            max: [
                self.max[0].max(o.max[0]),
                self.max[1].max(o.max[1]),
                self.max[2].max(o.max[2]),
            ],
        }
    }

    fn centroid(&self, axis: usize) -> f64 {
        0.5 * (self.min[axis] + self.max[axis])
    }

    /// Whether two boxes overlap (closed).
    pub fn overlaps(&self, o: &Aabb) -> bool {
        (0..3).all(|k| self.min[k] <= o.max[k] && o.min[k] <= self.max[k])
    }

    /// Whether the box contains the point (closed).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        (0..3).all(|k| self.min[k] <= p[k] && p[k] <= self.max[k])
    }

    /// The parameter interval `[t0, t1] ⊂ [0, t_max]` over which `o + t d` is inside the
    /// box, or `None` (the slab method; a zero direction component is handled by an
    /// explicit inside test so that no 0·∞ NaN appears).
    pub fn clip(&self, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<(f64, f64)> {
        let mut t0 = 0.0f64;
        let mut t1 = t_max;
        for k in 0..3 {
            if d[k] == 0.0 {
                if o[k] < self.min[k] || o[k] > self.max[k] {
                    return None;
                }
            } else {
                let inv = 1.0 / d[k];
                let (mut a, mut b) = ((self.min[k] - o[k]) * inv, (self.max[k] - o[k]) * inv);
                if a > b {
                    std::mem::swap(&mut a, &mut b);
                }
                t0 = t0.max(a);
                t1 = t1.min(b);
                if t0 > t1 {
                    return None;
                }
            }
        }
        Some((t0, t1))
    }
}

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// For a leaf: the first index into `order`; for an inner node: the right child's
    /// node index (the left child is the next node).
    index: u32,
    /// Number of primitives for a leaf; 0 for an inner node.
    count: u32,
}

/// A BVH over primitives identified by their position in the slice given to [`Bvh::build`].
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
    /// The primitives' boxes, so a leaf tests each before calling back: the exact test a
    /// caller runs next (a polygon against a segment) costs far more than a box.
    boxes: Vec<Aabb>,
}

impl Bvh {
    /// Builds the hierarchy over `boxes` (primitive `i` has box `boxes[i]`).
    pub fn build(boxes: &[Aabb]) -> Self {
        let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * boxes.len() / LEAF_SIZE + 1);
        if !boxes.is_empty() {
            build_rec(boxes, &mut order, 0, &mut nodes);
        }
        Self {
            nodes,
            order,
            boxes: boxes.to_vec(),
        }
    }

    /// Whether there are no primitives.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The box around everything, or [`Aabb::EMPTY`].
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }

    /// Calls `visit(i)` for exactly the primitives whose boxes the segment `o + t d`, `t ∈ [0, 1]`,
    /// passes through; `visit` returns `true` to stop the traversal early. Returns whether
    /// it was stopped.
    pub fn segment(&self, o: [f64; 3], d: [f64; 3], mut visit: impl FnMut(u32) -> bool) -> bool {
        self.traverse(|b| b.clip(o, d, 1.0).is_some(), &mut visit)
    }

    /// Calls `visit(i)` for exactly the primitives whose boxes overlap `query`; early stop as for
    /// [`Bvh::segment`].
    pub fn overlapping(&self, query: &Aabb, mut visit: impl FnMut(u32) -> bool) -> bool {
        self.traverse(|b| b.overlaps(query), &mut visit)
    }

    fn traverse(
        &self,
        mut hit: impl FnMut(&Aabb) -> bool,
        visit: &mut impl FnMut(u32) -> bool,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut stack = [0u32; STACK];
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let ni = stack[sp];
            let node = &self.nodes[ni as usize];
            if !hit(&node.bounds) {
                continue;
            }
            if node.count > 0 {
                let first = node.index as usize;
                for &p in &self.order[first..first + node.count as usize] {
                    if hit(&self.boxes[p as usize]) && visit(p) {
                        return true;
                    }
                }
            } else {
                // The left child follows its parent in depth-first order; it is pushed
                // last so it is visited first. The stack cannot overflow: its depth bound
                // is argued at `STACK`.
                stack[sp] = node.index;
                stack[sp + 1] = ni + 1;
                sp += 2;
            }
        }
        false
    }
}

fn build_rec(boxes: &[Aabb], order: &mut [u32], first: usize, nodes: &mut Vec<Node>) -> u32 {
    let bounds = order
        .iter()
        .fold(Aabb::EMPTY, |acc, &i| acc.union(&boxes[i as usize]));
    let me = nodes.len() as u32;
    if order.len() <= LEAF_SIZE {
        nodes.push(Node {
            bounds,
            index: first as u32,
            count: order.len() as u32,
        });
        return me;
    }
    // Split on the longest axis of the centroids' extent, at the median.
    let mut cmin = [f64::INFINITY; 3];
    let mut cmax = [f64::NEG_INFINITY; 3];
    for &i in order.iter() {
        for k in 0..3 {
            let c = boxes[i as usize].centroid(k);
            cmin[k] = cmin[k].min(c);
            cmax[k] = cmax[k].max(c);
        }
    }
    let axis = (0..3)
        .max_by(|&a, &b| (cmax[a] - cmin[a]).total_cmp(&(cmax[b] - cmin[b])))
        .unwrap_or(0);
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        boxes[a as usize]
            .centroid(axis)
            .total_cmp(&boxes[b as usize].centroid(axis))
    });
    nodes.push(Node {
        bounds,
        index: 0,
        count: 0,
    });
    let (left, right) = order.split_at_mut(mid);
    build_rec(boxes, left, first, nodes);
    let r = build_rec(boxes, right, first + mid, nodes);
    nodes[me as usize].index = r;
    me
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use rand::Rng;

    #[test]
    fn bvh_visits_exactly_the_boxes_a_brute_force_scan_finds() {
        // The hierarchy may only prune, never lose a box: compare its visits with a scan
        // over every box for random segments and random query boxes.
        let mut rng = TrialRng::new(5, 0).stream("test/bvh");
        let boxes: Vec<Aabb> = (0..500)
            .map(|_| {
                let x = rng.random_range(0.0..1000.0);
                let y = rng.random_range(0.0..1000.0);
                let (w, d, h) = (
                    rng.random_range(1.0..40.0),
                    rng.random_range(1.0..40.0),
                    rng.random_range(1.0..80.0),
                );
                Aabb {
                    min: [x, y, 0.0],
                    max: [x + w, y + d, h],
                }
            })
            .collect();
        let bvh = Bvh::build(&boxes);
        for _ in 0..300 {
            let o = [
                rng.random_range(-50.0..1050.0),
                rng.random_range(-50.0..1050.0),
                rng.random_range(0.0..90.0),
            ];
            let d = [
                rng.random_range(-500.0..500.0),
                rng.random_range(-500.0..500.0),
                rng.random_range(-60.0..60.0),
            ];
            let mut got = Vec::new();
            bvh.segment(o, d, |i| {
                got.push(i);
                false
            });
            got.sort_unstable();
            let want: Vec<u32> = (0..boxes.len() as u32)
                .filter(|&i| boxes[i as usize].clip(o, d, 1.0).is_some())
                .collect();
            assert_eq!(got, want);
            let q = Aabb {
                min: o,
                max: [o[0] + 30.0, o[1] + 30.0, o[2] + 5.0],
            };
            let mut got = Vec::new();
            bvh.overlapping(&q, |i| {
                got.push(i);
                false
            });
            got.sort_unstable();
            let want: Vec<u32> = (0..boxes.len() as u32)
                .filter(|&i| boxes[i as usize].overlaps(&q))
                .collect();
            assert_eq!(got, want);
        }
        assert!(Bvh::build(&[]).is_empty());
    }
}
