//! What the rasteriser draws into: a pixel rectangle of an image, and a target over one
//! (depth and class per pixel).

/// Per-pixel class of a rendered model.
pub const CLASS_NONE: u8 = 0;
pub const CLASS_BODY: u8 = 1;
pub const CLASS_BOI: u8 = 2;

/// A pixel rectangle `[x0, x0 + width) x [y0, y0 + height)` of an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
}

impl Rect {
    pub fn full(width: u32, height: u32) -> Rect {
        Rect {
            x0: 0,
            y0: 0,
            width,
            height,
        }
    }
    pub fn area(&self) -> u64 {
        self.width as u64 * self.height as u64
    }
    /// The overlap of two rectangles. An empty overlap is empty both ways (zero width and
    /// height), so that a walk over its rows does nothing: rectangles that share rows but not
    /// columns have no rows in common either.
    pub fn intersection(&self, o: &Rect) -> Rect {
        let x0 = self.x0.max(o.x0);
        let y0 = self.y0.max(o.y0);
        let x1 = (self.x0 + self.width).min(o.x0 + o.width);
        let y1 = (self.y0 + self.height).min(o.y0 + o.height);
        if x1 <= x0 || y1 <= y0 {
            return Rect {
                x0,
                y0,
                width: 0,
                height: 0,
            };
        }
        Rect {
            x0,
            y0,
            width: x1 - x0,
            height: y1 - y0,
        }
    }
    pub fn union(&self, o: &Rect) -> Rect {
        if self.area() == 0 {
            return *o;
        }
        if o.area() == 0 {
            return *self;
        }
        let x0 = self.x0.min(o.x0);
        let y0 = self.y0.min(o.y0);
        let x1 = (self.x0 + self.width).max(o.x0 + o.width);
        let y1 = (self.y0 + self.height).max(o.y0 + o.height);
        Rect {
            x0,
            y0,
            width: x1 - x0,
            height: y1 - y0,
        }
    }
}

/// A render target covering `rect` of the image: depth (1/z, 0 = empty) and class per pixel.
#[derive(Debug, Clone, Default)]
pub struct Target {
    pub rect: Option<Rect>,
    pub inv_depth: Vec<f32>,
    pub class: Vec<u8>,
}

impl Target {
    /// Copy `from`'s pixels inside this target's rectangle (a target just reset, drawn next).
    pub fn copy_from(&mut self, from: &Target) {
        let (Some(to), Some(src)) = (self.rect, from.rect) else {
            return;
        };
        let r = to.intersection(&src);
        let w = r.width as usize;
        for y in r.y0..r.y0 + r.height {
            let at = |rect: &Rect| {
                (y - rect.y0) as usize * rect.width as usize + (r.x0 - rect.x0) as usize
            };
            let (i, j) = (at(&to), at(&src));
            self.inv_depth[i..i + w].copy_from_slice(&from.inv_depth[j..j + w]);
            self.class[i..i + w].copy_from_slice(&from.class[j..j + w]);
        }
    }

    /// Reset to an empty target over `rect`, reusing the allocation.
    pub fn reset(&mut self, rect: Rect) {
        let n = rect.area() as usize;
        self.rect = Some(rect);
        self.inv_depth.clear();
        self.inv_depth.resize(n, 0.0);
        self.class.clear();
        self.class.resize(n, CLASS_NONE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(x0: u32, y0: u32, width: u32, height: u32) -> Rect {
        Rect {
            x0,
            y0,
            width,
            height,
        }
    }

    /// Found by hostile input: an arch far to the side put its footprint beside the other
    /// arch's rectangle, in the same rows; the overlap kept its height and the copy indexed
    /// past the end (energy/raster.rs:105 at bf99878).
    #[test]
    fn rectangles_sharing_rows_but_not_columns_copy_nothing() {
        let (a, b) = (rect(0, 10, 20, 30), rect(500, 0, 40, 60));
        assert_eq!(a.intersection(&b).area(), 0);
        assert_eq!(a.intersection(&b).height, 0);
        let mut to = Target::default();
        to.reset(a);
        let mut from = Target::default();
        from.reset(b);
        from.class.iter_mut().for_each(|c| *c = 1);
        to.copy_from(&from);
        assert!(to.class.iter().all(|&c| c == CLASS_NONE));
    }

    #[test]
    fn overlapping_rectangles_copy_their_overlap() {
        let (a, b) = (rect(0, 0, 10, 10), rect(5, 5, 10, 10));
        assert_eq!(a.intersection(&b), rect(5, 5, 5, 5));
        let mut to = Target::default();
        to.reset(a);
        let mut from = Target::default();
        from.reset(b);
        from.class.iter_mut().for_each(|c| *c = 2);
        to.copy_from(&from);
        assert_eq!(to.class.iter().filter(|&&c| c == 2).count(), 25);
    }
}
