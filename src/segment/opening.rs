//! The mouth's opening: the camera sees the interior through a hole in the lips, so lips and
//! skin are one region around it, reaching out of the picture's region of interest. Whatever
//! is coloured like lips or skin but lies inside the opening (the gums beyond the crowns, the
//! tongue, both as pink as the lips) is the mouth interior as the capture format defines it:
//! where the camera sees no tooth, inside the lips.

/// `classes` (row-major, `w` x `h`: 0 teeth, 1 mouth interior, 2 lips and skin) with every
/// 4-connected region of lips and skin that does not reach the border and touches the mouth
/// interior made mouth interior, but for its pixels within [`TEETH_MARGIN_PX`] of a tooth. A
/// region enclosed by teeth alone (a highlight on enamel) stays as it is: it is no sight of the
/// interior.
/// How far (pixels) from the teeth the opening's lip-coloured pixels stay unlabelled: one
/// there is as likely a crown's shaded or blurred edge as gum, and a model drawn over the
/// interior label pays for it, so a tooth's edge mislabelled so pushes the arch off.
const TEETH_MARGIN_PX: f32 = 2.0;

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
            let near = [
                (x > 0).then(|| i - 1),
                (x + 1 < w).then(|| i + 1),
                (y > 0).then(|| i - w),
                (y + 1 < h).then(|| i + w),
            ];
            for j in near.into_iter().flatten() {
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
    out
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let (w, h) = (rows[0].len(), rows.len());
        let classes: Vec<u8> = rows
            .iter()
            .flat_map(|r| r.bytes().map(|b| b - b'0'))
            .collect();
        let out = inside_the_lips(&classes, w, h);
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
