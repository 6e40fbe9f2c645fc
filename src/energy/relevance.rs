//! Which of the scored arch's body faces can change what the energy reads ([`Region::Relevant`]).
//!
//! E reads, per pixel, whether an arch-labelled pixel is covered (uncovered), whether a pixel
//! off the arch's label shows the boundary of interest (BOI outside), whether the other
//! arch's pixels show this arch (cross) and whether mouth-interior pixels show a model
//! (over-mouth). A body face drawn over pixels that carry no label changes none of these,
//! unless the BOI could be drawn there too (a body face in front hides it). So a body face, or a whole cluster of them, can be skipped when its
//! pixel bounds hold no labelled pixel and miss the rectangle the BOI can cover: the energy,
//! cross, over-mouth and area error stay exact; only the count of body pixels off the mask drops.
//!
//! [`Region::Relevant`]: super::Region::Relevant

use super::raster::{Bounds, Rect};
use crate::capture::LabelMask;

/// Side of a tile, as a power of two (4 x 4 pixels).
const TILE_SHIFT: u32 = 2;

/// Which tiles of a mask hold a pixel with any of some labels, as a summed-area table: how
/// many labelled tiles any rectangle of tiles holds, in four lookups.
#[derive(Debug, Clone, Default)]
pub struct LabelledTiles {
    /// Tiles per row, plus one (the table's leading zero column).
    stride: usize,
    /// `sum[ty * stride + tx]`: labelled tiles above and left of tile (tx, ty), exclusive.
    sum: Vec<u32>,
}

impl LabelledTiles {
    pub fn new(mask: &LabelMask, labels: u8) -> Self {
        let columns = (mask.width as usize).div_ceil(1 << TILE_SHIFT);
        let rows = (mask.height as usize).div_ceil(1 << TILE_SHIFT);
        let mut labelled = vec![false; columns * rows];
        for (y, row) in mask.data.chunks_exact(mask.width as usize).enumerate() {
            let tiles = &mut labelled[(y >> TILE_SHIFT) * columns..][..columns];
            for (x, &m) in row.iter().enumerate() {
                tiles[x >> TILE_SHIFT] |= m & labels != 0;
            }
        }
        let stride = columns + 1;
        let mut sum = vec![0u32; stride * (rows + 1)];
        for ty in 0..rows {
            let mut in_row = 0;
            for tx in 0..columns {
                in_row += labelled[ty * columns + tx] as u32;
                sum[(ty + 1) * stride + tx + 1] = sum[ty * stride + tx + 1] + in_row;
            }
        }
        LabelledTiles { stride, sum }
    }

    /// Whether a tile overlapping `b` holds a labelled pixel (`b` lies within the mask).
    #[inline]
    fn any_within(&self, b: &Bounds) -> bool {
        let tile = |v: i64| (v >> TILE_SHIFT) as usize;
        let (tx0, tx1, ty0, ty1) = (tile(b.x0), tile(b.x1) + 1, tile(b.y0), tile(b.y1) + 1);
        let at = |tx: usize, ty: usize| self.sum[ty * self.stride + tx];
        at(tx1, ty1) + at(tx0, ty0) != at(tx0, ty1) + at(tx1, ty0)
    }
}

/// What decides whether body faces can change the energy, per camera and candidate.
pub struct Relevance<'a> {
    pub tiles: &'a LabelledTiles,
    /// The pixels the arch's BOI faces can cover.
    pub boi: Rect,
}

impl Relevance<'_> {
    /// Whether body faces within `b` can change the energy: `b` meets a labelled tile or the
    /// BOI's rectangle.
    #[inline]
    pub fn body_counts(&self, b: &Bounds) -> bool {
        let boi = &self.boi;
        let meets_boi = b.x0 < (boi.x0 + boi.width) as i64
            && b.x1 >= boi.x0 as i64
            && b.y0 < (boi.y0 + boi.height) as i64
            && b.y1 >= boi.y0 as i64;
        meets_boi || self.tiles.any_within(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_know_where_the_labels_are() {
        // A 30 x 20 mask with label 1 at (13, 9) and label 2 at (29, 19).
        let mut mask = LabelMask {
            soft: None,
            width: 30,
            height: 20,
            data: vec![0; 600],
        };
        mask.data[9 * 30 + 13] = 1;
        mask.data[19 * 30 + 29] = 2;
        let tiles = LabelledTiles::new(&mask, 1);
        let b = |x0, x1, y0, y1| Bounds { x0, x1, y0, y1 };
        // Label 1's tile is x 12..16, y 8..12.
        assert!(tiles.any_within(&b(12, 12, 8, 8)));
        assert!(tiles.any_within(&b(0, 29, 0, 19)));
        assert!(tiles.any_within(&b(15, 20, 11, 11)));
        assert!(!tiles.any_within(&b(16, 29, 0, 19)));
        assert!(!tiles.any_within(&b(0, 11, 0, 19)));
        assert!(!tiles.any_within(&b(0, 29, 12, 19)));
        // Label 2 is not asked for; with it, the corner tile counts.
        assert!(!tiles.any_within(&b(28, 29, 16, 19)));
        assert!(LabelledTiles::new(&mask, 3).any_within(&b(28, 29, 16, 19)));
        let boi = Rect {
            x0: 20,
            y0: 0,
            width: 5,
            height: 5,
        };
        let r = Relevance { tiles: &tiles, boi };
        assert!(r.body_counts(&b(24, 26, 4, 6)));
        assert!(!r.body_counts(&b(25, 26, 4, 6)));
        assert!(!r.body_counts(&b(20, 24, 5, 6)));
        assert!(r.body_counts(&b(11, 12, 7, 8)));
    }
}
