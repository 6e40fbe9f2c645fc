//! The soft evidence beside the labels: how much of each pixel along the teeth's edges the
//! teeth hold, read from its colour as a mix of the two sides'. The labels round an edge to
//! whole pixels; a blurred edge's pixels hold both sides, and their mix says where between
//! them the edge lies. The smooth energy reads these shares in place of the labels
//! ([`crate::capture::LabelMask::soft`]), so a pixel 60 % teeth moves the edge it sees by a
//! fraction of a pixel, where its label moved it by a whole one.

use super::edges::{linear_colours, local_mean, mix, rim};

/// `classes` (row-major, `w` x `h`: 0 teeth, 1 mouth interior, 2 lips and skin): per pixel,
/// the share of it the teeth hold, 0-255. 255 on teeth and 0 elsewhere, but at an edge
/// between teeth and the rest (4-neighbours), where it is the pixel's colour read as a mix of
/// the two sides' *rims*, held to the side its label took: at least half on teeth, less than
/// half off them. Where the two sides' colours are alike the label stands.
///
/// A rim is the side's colour just behind the edge pixels (the one behind the tooth's edge
/// pixel and the one beyond its neighbour across the edge, each with its two neighbours along
/// the edge), not the side's mean further in: a crown darkens towards its silhouette as it
/// turns from the light, and read against the bright middle of the crown its edge pixels hold
/// too little of it. Where a rim pixel is of another class (a thin gap), the side's local mean
/// over `inner` pixels stands in, as [`super::edges::refine_edges`] reads it.
pub(super) fn teeth_shares(
    colours: &[[u8; 3]],
    classes: &[u8],
    inner: &[u8],
    w: usize,
    h: usize,
) -> Vec<u8> {
    let lin = linear_colours(colours);
    let mut out: Vec<u8> = classes
        .iter()
        .map(|&c| if c == 0 { 255 } else { 0 })
        .collect();
    let (wi, hi) = (w as isize, h as isize);
    let pixel =
        |x: isize, y: isize| (x >= 0 && y >= 0 && x < wi && y < hi).then(|| (y * wi + x) as usize);
    for y in 0..hi {
        for x in 0..wi {
            let i = (y * wi + x) as usize;
            let teeth = classes[i] == 0;
            // The first 4-neighbour across the edge, (dx, dy) towards it.
            let Some((d, j)) =
                [(-1, 0), (1, 0), (0, -1), (0, 1)]
                    .into_iter()
                    .find_map(|(dx, dy)| {
                        let j = pixel(x + dx, y + dy)?;
                        ((classes[j] == 0) != teeth).then_some(((dx, dy), j))
                    })
            else {
                continue;
            };
            let (dx, dy) = d;
            let (behind, beyond) = ((x - dx, y - dy), (x + 2 * dx, y + 2 * dy));
            let (teeth_at, rest_at, rest) = if teeth {
                (behind, beyond, classes[j])
            } else {
                (beyond, behind, classes[i])
            };
            let side = |(rx, ry): (isize, isize), class: u8| {
                rim(&lin, classes, w, h, (rx, ry), d, class)
                    .or_else(|| local_mean(&lin, inner, w, h, x as usize, y as usize, class))
            };
            let (Some(t), Some(r)) = (side(teeth_at, 0), side(rest_at, rest)) else {
                continue;
            };
            let Some((share, _)) = mix(lin[i], t, r) else {
                continue;
            };
            let byte = (share.clamp(0.0, 1.0) * 255.0).round() as u8;
            out[i] = if teeth { byte.max(128) } else { byte.min(127) };
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector2;

    use super::*;
    use crate::capture::light::{encoded, linear};
    use crate::energy::contour::{ContourPoint, bilinear_by};
    use crate::energy::edge_terms::edge_offset;

    /// A crown's edge at `edge` (x, pixels; pixel k spans k - 0.5..k + 0.5) against the dark
    /// interior, each pixel's light the mix its coverage says, blurred by a lens ([1 2 1] / 4)
    /// and encoded: where the labels (teeth where at least half covered) and the shares put
    /// the edge, read as the smooth energy reads a mask.
    fn edges_found(edge: f64) -> (f64, f64) {
        let (w, h) = (16usize, 9usize);
        let pale = [230u8, 220, 200].map(linear);
        let dark = [60u8, 20, 25].map(linear);
        let cover = |x: usize| (edge - (x as f64 - 0.5)).clamp(0.0, 1.0) as f32;
        let light = |x: usize| -> [f32; 3] {
            std::array::from_fn(|k| cover(x) * pale[k] + (1.0 - cover(x)) * dark[k])
        };
        let blurred = |x: usize| -> [u8; 3] {
            let (a, b, c) = (
                light(x.saturating_sub(1)),
                light(x),
                light((x + 1).min(w - 1)),
            );
            std::array::from_fn(|k| {
                encoded((0.25 * a[k] + 0.5 * b[k] + 0.25 * c[k]) as f64).round() as u8
            })
        };
        let colours: Vec<[u8; 3]> = (0..w * h).map(|i| blurred(i % w)).collect();
        let classes: Vec<u8> = (0..w * h)
            .map(|i| if cover(i % w) >= 0.5 { 0 } else { 1 })
            .collect();
        let inner: Vec<u8> = (0..w * h)
            .map(|i| {
                let x = i % w;
                let near = (x.saturating_sub(2)..(x + 3).min(w)).any(|k| classes[k] != classes[x]);
                if near { 3 } else { classes[i] }
            })
            .collect();
        let shares = teeth_shares(&colours, &classes, &inner, w, h);
        let found = |value: &dyn Fn(usize) -> f64| {
            let read = |p: Vector2<f64>| bilinear_by(w, h, value, p);
            let at = ContourPoint {
                pixel: Vector2::new(4.0, 4.0),
                normal: Vector2::x(),
                length: 1.0,
                inv_depth: 0.005,
                jacobian: nalgebra::Matrix2x6::zeros(),
            };
            4.0 + edge_offset(&at, &read, 8.0).expect("an edge")
        };
        (
            found(&|i| (classes[i] == 0) as u8 as f64),
            found(&|i| shares[i] as f64 / 255.0),
        )
    }

    /// Where the edge falls within a pixel, the shares find it within a fifth of a pixel (the
    /// rims are blurred a little too, which pulls it towards the labels' edge); the labels
    /// alone round it to the pixel's side, up to half a pixel off.
    #[test]
    fn the_shares_put_a_blurred_edge_within_its_pixel() {
        let mut worst = [0f64; 2];
        for edge in [6.55, 6.8, 7.0, 7.2, 7.45] {
            let (labels, shares) = edges_found(edge);
            eprintln!("edge {edge}: labels {labels:.3}, shares {shares:.3}");
            worst[0] = worst[0].max((labels - edge).abs());
            worst[1] = worst[1].max((shares - edge).abs());
        }
        assert!(worst[1] < 0.2, "{worst:?}");
        assert!(worst[0] > 0.4, "{worst:?}");
    }
}
