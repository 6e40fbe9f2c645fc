//! Packing a batch's tiles (one per candidate and camera) into square atlas pages, shelf by
//! shelf. A batch that does not fit one page is rendered and counted page after page in the
//! same submission.

/// Side of an atlas page (pixels); masks up to this size are supported.
pub const PAGE: u32 = 4096;
/// A dispatch's z extent is at most 65535 workgroups.
pub const MAX_TILES_PER_PAGE: usize = 65535;

/// Where a tile of `width x height` lands: page and origin in that page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Placement {
    pub page: usize,
    pub x: u32,
    pub y: u32,
}

/// Shelf packing in input order into pages of `side x side`; at most `max_per_page` tiles a
/// page (a dispatch's z extent). Every size must fit a page.
pub fn pack(sizes: &[(u32, u32)], side: u32, max_per_page: usize) -> Vec<Placement> {
    let mut out = Vec::with_capacity(sizes.len());
    let (mut page, mut x, mut y, mut shelf_h, mut on_page) = (0usize, 0u32, 0u32, 0u32, 0usize);
    for &(w, h) in sizes {
        debug_assert!(
            w <= side && h <= side,
            "tile {w}x{h} larger than a {side} page"
        );
        if x + w > side {
            x = 0;
            y += shelf_h;
            shelf_h = 0;
        }
        if y + h > side || on_page == max_per_page {
            page += 1;
            x = 0;
            y = 0;
            shelf_h = 0;
            on_page = 0;
        }
        out.push(Placement { page, x, y });
        x += w;
        shelf_h = shelf_h.max(h);
        on_page += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_never_overlap_and_stay_inside_their_page() {
        let sizes: Vec<(u32, u32)> = (0..300)
            .map(|i| (17 + (i * 37) % 300, 9 + (i * 53) % 200))
            .collect();
        let placed = pack(&sizes, 1024, 50);
        for (i, (p, s)) in placed.iter().zip(&sizes).enumerate() {
            assert!(p.x + s.0 <= 1024 && p.y + s.1 <= 1024);
            for (q, t) in placed[..i].iter().zip(&sizes) {
                let apart = p.page != q.page
                    || p.x + s.0 <= q.x
                    || q.x + t.0 <= p.x
                    || p.y + s.1 <= q.y
                    || q.y + t.1 <= p.y;
                assert!(apart, "tiles {i} and another overlap");
            }
        }
        assert!(
            placed.last().unwrap().page >= 5,
            "300 tiles, at most 50 a page"
        );
    }
}
