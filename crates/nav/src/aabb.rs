//! Axis-aligned bounding boxes in model coordinates (f64).

use std::borrow::Borrow;

use glam::DVec3;

/// An axis-aligned box in model coordinates. [`Aabb::EMPTY`] (min = +inf, max = -inf)
/// is the neutral element of [`Aabb::union`] and is not [valid](Aabb::is_valid).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: DVec3,
    /// Largest corner.
    pub max: DVec3,
}

impl Aabb {
    /// The empty box: contains nothing, `union` with it changes nothing.
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::INFINITY,
        max: DVec3::NEG_INFINITY,
    };

    /// A box from its corners (not reordered: `min > max` on an axis makes it invalid).
    pub fn new(min: DVec3, max: DVec3) -> Aabb {
        Aabb { min, max }
    }

    /// A box from corner arrays (a model header's bounds).
    pub fn from_arrays(min: [f64; 3], max: [f64; 3]) -> Aabb {
        Aabb::new(DVec3::from_array(min), DVec3::from_array(max))
    }

    /// The smallest box holding every finite point (non-finite points are skipped);
    /// [`Aabb::EMPTY`] for none.
    pub fn from_points<I>(points: I) -> Aabb
    where
        I: IntoIterator,
        I::Item: Borrow<DVec3>,
    {
        let mut b = Aabb::EMPTY;
        for p in points {
            b.include(*p.borrow());
        }
        b
    }

    /// Grows the box to hold `p` (ignored when not finite).
    pub fn include(&mut self, p: DVec3) {
        if p.is_finite() {
            self.min = self.min.min(p);
            self.max = self.max.max(p);
        }
    }

    /// The smallest box holding both.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb::new(self.min.min(other.min), self.max.max(other.max))
    }

    /// True when finite and `min <= max` on every axis (a flat box or a single point is
    /// valid).
    pub fn is_valid(&self) -> bool {
        self.min.is_finite() && self.max.is_finite() && self.min.cmple(self.max).all()
    }

    /// The centre.
    pub fn center(&self) -> DVec3 {
        0.5 * (self.min + self.max)
    }

    /// `max - min`.
    pub fn size(&self) -> DVec3 {
        self.max - self.min
    }

    /// Half the diagonal: the radius of the smallest sphere around the centre that
    /// holds the box.
    pub fn radius(&self) -> f64 {
        0.5 * self.size().length()
    }

    /// The eight corners (bit i of the index selects max on axis i).
    pub fn corners(&self) -> [DVec3; 8] {
        std::array::from_fn(|i| {
            DVec3::new(
                if i & 1 == 0 { self.min.x } else { self.max.x },
                if i & 2 == 0 { self.min.y } else { self.max.y },
                if i & 4 == 0 { self.min.z } else { self.max.z },
            )
        })
    }

    /// True when `p` lies in the box (borders included).
    pub fn contains(&self, p: DVec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }
}
