//! Boxes, points and sizes in pixel coordinates.
//!
//! Coordinates are 0-based with pixel `i` covering `[i, i + 1)`: a box `x, y, w, h`
//! spans `[x, x + w) × [y, y + h)` and its centre is `(x + w/2, y + h/2)`.

use serde::{Deserialize, Serialize};

/// An axis-aligned box: top-left corner and size, pixels, 0-based.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct BBox {
    /// Left edge.
    pub x: f32,
    /// Top edge.
    pub y: f32,
    /// Width.
    pub w: f32,
    /// Height.
    pub h: f32,
}

impl BBox {
    /// A box from its corner and size.
    pub const fn new(x: f32, y: f32, w: f32, h: f32) -> Self {
        Self { x, y, w, h }
    }

    /// A box of size `size` centred on `center`.
    pub fn from_center(center: Point2, size: Size2) -> Self {
        Self::new(
            center.x - size.w / 2.0,
            center.y - size.h / 2.0,
            size.w,
            size.h,
        )
    }

    /// The centre point.
    pub fn center(&self) -> Point2 {
        Point2 {
            x: self.x + self.w / 2.0,
            y: self.y + self.h / 2.0,
        }
    }

    /// The size.
    pub fn size(&self) -> Size2 {
        Size2 {
            w: self.w,
            h: self.h,
        }
    }

    /// Area, px² (0 for a degenerate box).
    pub fn area(&self) -> f32 {
        self.w.max(0.0) * self.h.max(0.0)
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.w.is_finite() && self.h.is_finite()
    }

    /// Intersection with another box (zero-sized when disjoint).
    pub fn intersect(&self, o: &BBox) -> BBox {
        let x0 = self.x.max(o.x);
        let y0 = self.y.max(o.y);
        let x1 = (self.x + self.w).min(o.x + o.w);
        let y1 = (self.y + self.h).min(o.y + o.h);
        BBox::new(x0, y0, (x1 - x0).max(0.0), (y1 - y0).max(0.0))
    }

    /// Intersection over union in [0, 1]; 0 when either box is empty.
    pub fn iou(&self, o: &BBox) -> f32 {
        let i = self.intersect(o).area();
        let u = self.area() + o.area() - i;
        if u > 0.0 {
            i / u
        } else {
            0.0
        }
    }
}

/// A point, pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point2 {
    /// Column coordinate.
    pub x: f32,
    /// Row coordinate.
    pub y: f32,
}

impl Point2 {
    /// Euclidean distance to another point.
    pub fn distance(&self, o: &Point2) -> f32 {
        (self.x - o.x).hypot(self.y - o.y)
    }
}

/// A size, pixels (or cells where stated).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Size2 {
    /// Width.
    pub w: f32,
    /// Height.
    pub h: f32,
}

/// Integer grid size: rows × columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct GridSize {
    /// Rows.
    pub h: usize,
    /// Columns.
    pub w: usize,
}

impl GridSize {
    /// Number of elements.
    pub const fn len(&self) -> usize {
        self.h * self.w
    }
    /// True for an empty grid.
    pub const fn is_empty(&self) -> bool {
        self.h == 0 || self.w == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_of_identical_boxes_is_one_and_disjoint_is_zero() {
        let a = BBox::new(0.0, 0.0, 10.0, 10.0);
        assert!((a.iou(&a) - 1.0).abs() < 1e-6);
        let b = BBox::new(20.0, 0.0, 10.0, 10.0);
        assert_eq!(a.iou(&b), 0.0);
    }

    #[test]
    fn iou_of_half_overlap_is_one_third() {
        let a = BBox::new(0.0, 0.0, 10.0, 10.0);
        let b = BBox::new(5.0, 0.0, 10.0, 10.0);
        assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-6);
    }

    #[test]
    fn center_round_trips_through_from_center() {
        let a = BBox::new(3.0, 4.0, 11.0, 7.0);
        let b = BBox::from_center(a.center(), a.size());
        assert_eq!(a, b);
    }
}
