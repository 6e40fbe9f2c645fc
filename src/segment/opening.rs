//! The mouth's opening: the camera sees the interior through a hole in the lips, so lips and
//! skin are one region around it, reaching out of the picture's region of interest. Whatever
//! is coloured like lips or skin but lies inside the opening (the gums beyond the crowns, the
//! tongue, both as pink as the lips) is the mouth interior as the capture format defines it:
//! where the camera sees no tooth, inside the lips. What no region of lip colour encloses (a
//! tongue or gums that reach the lips) the opening's outline, its convex hull, still holds.

use super::edges::neighbours4;

/// How far (pixels) from the teeth the opening's lip-coloured pixels stay unlabelled: one
/// there is as likely a crown's shaded or blurred edge as gum, and a model drawn over the
/// interior label pays for it, so a tooth's edge mislabelled so pushes the arch off.
const TEETH_MARGIN_PX: f32 = 2.0;

/// `classes` (row-major, `w` x `h`: 0 teeth, 1 mouth interior, 2 lips and skin) with the
/// lips and skin inside the opening made mouth interior, but for pixels within
/// [`TEETH_MARGIN_PX`] of a tooth. Inside is what the lips enclose with the interior (a
/// 4-connected region that does not reach the border and touches the interior) or what the
/// convex hull of the opening (teeth and interior) covers. A region enclosed by teeth alone
/// (a highlight on enamel) stays as it is: it is no sight of the interior.
pub(super) fn inside_the_lips(classes: &[u8], w: usize, h: usize) -> Vec<u8> {
    let mut out = classes.to_vec();
    let teeth: Vec<u8> = classes.iter().map(|&c| (c == 0) as u8).collect();
    let (teeth_distance, _) = super::distance::distance_transform(&teeth, w, h);
    let mut seen = vec![false; classes.len()];
    let mut region = Vec::new();
    for start in 0..classes.len() {
        if seen[start] || classes[start] != 2 {
            continue;
        }
        // One region, breadth first, noting whether it reaches the border or the interior.
        region.clear();
        region.push(start);
        seen[start] = true;
        let (mut border, mut interior) = (false, false);
        let mut next = 0;
        while next < region.len() {
            let i = region[next];
            next += 1;
            let (x, y) = (i % w, i / w);
            border |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
            for j in neighbours4(w, h, x, y) {
                match classes[j] {
                    2 if !seen[j] => {
                        seen[j] = true;
                        region.push(j);
                    }
                    1 => interior = true,
                    _ => {}
                }
            }
        }
        if interior && !border {
            for &i in &region {
                if teeth_distance[i] > TEETH_MARGIN_PX {
                    out[i] = 1;
                }
            }
        }
    }
    // The tongue and the gums often reach the lips, so no region encloses them: the opening's
    // outline is what does. A mouth's opening is convex but where a lip bulges into it, so
    // its hull holds them and little lip.
    if let Some(hull) = opening_hull(classes, w, h) {
        for (y, span) in hull.iter().enumerate() {
            let Some((x0, x1)) = *span else { continue };
            for x in x0..=x1 {
                let i = y * w + x;
                if out[i] == 2 && teeth_distance[i] > TEETH_MARGIN_PX {
                    out[i] = 1;
                }
            }
        }
    }
    out
}

/// Per row, the columns (inclusive) that the convex hull of the opening's pieces
/// ([`opening_pieces`]) covers; `None` when the largest shows no interior (a closed mouth's
/// teeth enclose no lip).
fn opening_hull(classes: &[u8], w: usize, h: usize) -> Option<Vec<Option<(usize, usize)>>> {
    let piece = opening_pieces(classes, w, h)?;
    // Each row's ends are enough for the hull.
    let mut ends: Vec<(i64, i64)> = Vec::new();
    for y in 0..h {
        let row = &piece[y * w..(y + 1) * w];
        if let (Some(a), Some(b)) = (row.iter().position(|&p| p), row.iter().rposition(|&p| p)) {
            ends.push((a as i64, y as i64));
            ends.push((b as i64, y as i64));
        }
    }
    let hull = convex_hull(ends);
    let mut spans = vec![None; h];
    for (y, span) in spans.iter_mut().enumerate() {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let y = y as f64;
        for k in 0..hull.len() {
            let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
            let (ya, yb) = (a.1 as f64, b.1 as f64);
            if y < ya.min(yb) || y > ya.max(yb) {
                continue;
            }
            let (x0, x1) = if ya == yb {
                (a.0.min(b.0) as f64, a.0.max(b.0) as f64)
            } else {
                let x = a.0 as f64 + (b.0 - a.0) as f64 * (y - ya) / (yb - ya);
                (x, x)
            };
            lo = lo.min(x0);
            hi = hi.max(x1);
        }
        if lo <= hi {
            *span = Some((lo.ceil() as usize, (hi.floor() as usize).min(w - 1)));
        }
    }
    Some(spans)
}

/// The smallest share of the largest piece's pixels that another piece of teeth or interior
/// needs to be part of the opening: a whole arch's crowns, cut off from the interior by the
/// tongue behind them or by the gums, are a sizeable share; a highlight on a lip is not.
const PIECE_SHARE: usize = 8;

/// The opening's pieces: the largest 4-connected piece of teeth and interior, if it holds any
/// interior, and every other piece at least 1/[`PIECE_SHARE`] of its size. The tongue behind
/// the lower incisors, or the gums, often cut one arch's crowns off from the interior; the
/// band between them lies inside the lips all the same.
fn opening_pieces(classes: &[u8], w: usize, h: usize) -> Option<Vec<bool>> {
    let open = |i: usize| classes[i] < 2;
    let mut piece_of = vec![u32::MAX; classes.len()];
    // Each piece's size and whether it holds interior.
    let mut pieces: Vec<(usize, bool)> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..classes.len() {
        if !open(start) || piece_of[start] != u32::MAX {
            continue;
        }
        let id = pieces.len() as u32;
        piece_of[start] = id;
        stack.push(start);
        let (mut size, mut interior) = (0usize, false);
        while let Some(i) = stack.pop() {
            size += 1;
            interior |= classes[i] == 1;
            for j in neighbours4(w, h, i % w, i / w) {
                if open(j) && piece_of[j] == u32::MAX {
                    piece_of[j] = id;
                    stack.push(j);
                }
            }
        }
        pieces.push((size, interior));
    }
    let &(largest, interior) = pieces.iter().max_by_key(|(size, _)| *size)?;
    let kept: Vec<bool> = pieces
        .iter()
        .map(|&(size, _)| size * PIECE_SHARE >= largest)
        .collect();
    interior.then(|| {
        piece_of
            .iter()
            .map(|&p| p != u32::MAX && kept[p as usize])
            .collect()
    })
}

/// The convex hull (Andrew's monotone chain), its vertices in order.
fn convex_hull(mut points: Vec<(i64, i64)>) -> Vec<(i64, i64)> {
    points.sort_unstable();
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let mut lower = half_hull(points.iter().copied());
    let mut upper = half_hull(points.iter().rev().copied());
    // Each half ends where the other starts.
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

/// One side of the hull of points sorted along x: the chain that turns one way only.
fn half_hull(points: impl Iterator<Item = (i64, i64)>) -> Vec<(i64, i64)> {
    let cross = |o: (i64, i64), a: (i64, i64), b: (i64, i64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut chain: Vec<(i64, i64)> = Vec::new();
    for p in points {
        while chain.len() >= 2 && cross(chain[chain.len() - 2], chain[chain.len() - 1], p) <= 0 {
            chain.pop();
        }
        chain.push(p);
    }
    chain
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`inside_the_lips`] of a picture drawn as rows of class digits, and its width.
    fn opened(rows: &[&str]) -> (Vec<u8>, usize) {
        let (w, h) = (rows[0].len(), rows.len());
        let classes: Vec<u8> = rows
            .iter()
            .flat_map(|r| r.bytes().map(|b| b - b'0'))
            .collect();
        (inside_the_lips(&classes, w, h), w)
    }

    /// A tongue that reaches the lips at the sides is enclosed by no region, but it lies
    /// within the opening's outline: interior, but for its pixels beside the teeth. The lips
    /// beyond the outline stay.
    #[test]
    fn what_the_opening_holds_is_interior_where_the_tongue_reaches_the_lips() {
        let rows = [
            "2222222222222222",
            "2220000220000222",
            "2211111111111122",
            "2211111111111122",
            "2211112222111122",
            "2221112222111222",
            "2222222222222222",
            "2222222222222222",
        ];
        let (out, w) = opened(&rows);
        let at = |x: usize, y: usize| out[y * w + x];
        assert_eq!(at(7, 4), 1, "the tongue, joined to the lower lip");
        assert_eq!(at(8, 5), 1);
        assert_eq!(at(7, 6), 2, "the lip below the opening");
        assert_eq!(at(2, 5), 2, "the lip beside it");
        assert_eq!(at(7, 1), 2, "between two crowns, within the margin");
        assert_eq!(at(0, 0), 2, "skin");
    }

    /// The tongue behind the lower incisors, reaching the lips at both corners, cuts the lower
    /// crowns off from the interior: the band between them is interior all the same (but for
    /// its pixels beside the crowns), and a highlight on the lower lip does not widen the
    /// opening.
    #[test]
    fn a_band_between_the_interior_and_crowns_cut_off_from_it_is_interior() {
        let rows = [
            "222222222222222222",
            "222000000000000222",
            "221111111111111122",
            "222222222222222222",
            "222222222222222222",
            "222222222222222222",
            "222222222222222222",
            "222000000000000222",
            "222222222222222222",
            "222222222222222202",
            "222222222222222222",
        ];
        let (out, w) = opened(&rows);
        let at = |x: usize, y: usize| out[y * w + x];
        assert_eq!(at(8, 4), 1, "the tongue, 3 px above the lower crowns");
        assert_eq!(at(8, 5), 2, "the tongue beside the lower crowns");
        assert_eq!(at(1, 4), 2, "the lip beside it");
        assert_eq!(at(16, 8), 2, "the lip beside the highlight");
    }

    /// Lips and skin around an opening; inside it, teeth above the interior with a tongue in
    /// it, and a highlight on a tooth: the tongue becomes interior but for its pixels beside
    /// the teeth; the lips and the highlight stay.
    #[test]
    fn what_the_lips_enclose_with_the_interior_is_interior() {
        let rows = [
            "2222222222222222",
            "2220000000000222",
            "2200200000000022",
            "2200000000000022",
            "2211112222111122",
            "2211122222211122",
            "2211122222211122",
            "2211112222111122",
            "2211111111111122",
            "2222211111122222",
            "2222222222222222",
        ];
        let (out, w) = opened(&rows);
        let at = |x: usize, y: usize| out[y * w + x];
        assert_eq!(at(7, 6), 1, "the tongue, 3 px below the teeth");
        assert_eq!(at(7, 7), 1);
        assert_eq!(at(7, 4), 2, "the tongue beside the teeth");
        assert_eq!(at(4, 2), 2, "a highlight enclosed by teeth");
        assert_eq!(at(0, 0), 2, "skin");
        assert_eq!(at(1, 6), 2, "a lip");
        assert_eq!(at(3, 6), 1);
    }
}
