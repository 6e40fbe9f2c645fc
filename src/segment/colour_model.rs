//! A colour model of one kind of surface (teeth, mouth interior, lips and skin): a histogram
//! over chromaticity (r and g of r+g+b, 24 levels each) and luma (8 levels), smoothed across
//! neighbouring bins so that colours a few levels apart count alike (sensor noise,
//! compression), learned per capture from the pixels the segmentation gave that class and
//! updated as tracking goes. Chromaticity apart from brightness keeps a tooth in its own
//! shadow a tooth: shading changes its luma, hardly its hue. The chromaticity levels are
//! fine enough (1/24, about 0.04) to keep shaded enamel apart from skin under a warm white
//! balance, whose chromaticities differ by about 0.04-0.05: at 1/16, smoothed, they share
//! their bins, and a side camera, whose view of the teeth borders the cheek, took crowns for
//! skin.

/// Levels along each axis: r chromaticity, g chromaticity, luma.
const AXES: [usize; 3] = [24, 24, 8];
const BINS: usize = AXES[0] * AXES[1] * AXES[2];
/// The density every bin keeps, as a share of the uniform density: no colour is impossible.
const FLOOR: f32 = 0.01;

#[derive(Debug, Clone)]
pub struct ColourModel {
    density: Vec<f32>,
}

fn bin(c: [u8; 3]) -> usize {
    let [r, g, b] = c.map(|v| v as f32);
    let sum = (r + g + b).max(1.0);
    let level = |v: f32, levels: usize| ((v * levels as f32) as usize).min(levels - 1);
    let (rc, gc) = (level(r / sum, AXES[0]), level(g / sum, AXES[1]));
    let l = level(luma(c) / 256.0, AXES[2]);
    (rc * AXES[1] + gc) * AXES[2] + l
}

pub fn luma(c: [u8; 3]) -> f32 {
    0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32
}

impl ColourModel {
    /// Learned from the colours given; `None` from fewer than `min_pixels`.
    pub fn learn(colours: impl Iterator<Item = [u8; 3]>, min_pixels: usize) -> Option<ColourModel> {
        let mut counts = vec![0f32; BINS];
        let mut n = 0usize;
        for c in colours {
            counts[bin(c)] += 1.0;
            n += 1;
        }
        if n < min_pixels.max(1) {
            return None;
        }
        // [1 2 1] / 4 along each channel.
        let strides = [AXES[1] * AXES[2], AXES[2], 1];
        for axis in 0..3 {
            let (stride, levels) = (strides[axis], AXES[axis]);
            let before = counts.clone();
            for (i, c) in counts.iter_mut().enumerate() {
                let level = i / stride % levels;
                let lo = if level > 0 {
                    before[i - stride]
                } else {
                    before[i]
                };
                let hi = if level + 1 < levels {
                    before[i + stride]
                } else {
                    before[i]
                };
                *c = 0.25 * lo + 0.5 * before[i] + 0.25 * hi;
            }
        }
        let floor = FLOOR * n as f32 / BINS as f32;
        let total: f32 = counts.iter().map(|c| c + floor).sum();
        Some(ColourModel {
            density: counts
                .iter()
                .map(|c| (c + floor) / total * BINS as f32)
                .collect(),
        })
    }

    /// The same surface in shade as well: each colour also at every lower luma level, its
    /// density falling by `falloff` a level. Shade scales a diffuse surface's brightness and
    /// keeps its chromaticity; the pixels a model is learned from are mostly lit.
    pub fn shaded(mut self, falloff: f32) -> ColourModel {
        let levels = AXES[2];
        for chroma in self.density.chunks_mut(levels) {
            for l in (0..levels - 1).rev() {
                chroma[l] = chroma[l].max(falloff * chroma[l + 1]);
            }
        }
        let total: f32 = self.density.iter().sum();
        for d in &mut self.density {
            *d *= BINS as f32 / total;
        }
        self
    }

    /// Every colour as likely as any: for a class with nothing yet to learn from.
    pub fn uniform() -> ColourModel {
        ColourModel {
            density: vec![1.0; BINS],
        }
    }

    /// Move towards `fresh` by `rate` (0: keep, 1: replace).
    pub fn update(&mut self, fresh: &ColourModel, rate: f32) {
        for (d, f) in self.density.iter_mut().zip(&fresh.density) {
            *d += rate * (f - *d);
        }
    }

    /// The density of a colour, relative to a uniform one (1: as likely as any).
    pub fn density(&self, c: [u8; 3]) -> f32 {
        self.density[bin(c)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_learned_colour_is_likelier_than_an_unseen_one_and_nothing_is_impossible() {
        let teeth = ColourModel::learn(
            (0..500).map(|k| [225 + (k % 7) as u8, 215, 190 + (k % 5) as u8]),
            10,
        )
        .unwrap();
        assert!(teeth.density([228, 216, 192]) > 100.0 * teeth.density([170, 80, 85]));
        assert!(teeth.density([0, 0, 255]) > 0.0);
        assert!(ColourModel::learn([[1, 2, 3]].into_iter(), 10).is_none());
    }

    /// Enamel learned lit; in shade (a third as bright, the same chromaticity) the plain
    /// model has it at its floor, the shaded one far above; brighter than lit, and other
    /// hues, gain nothing; the density stays a density.
    #[test]
    fn a_shaded_model_knows_its_colours_darker() {
        let lit = [225u8, 215, 190];
        let plain = ColourModel::learn((0..500).map(|_| lit), 10).unwrap();
        let shaded = plain.clone().shaded(0.7);
        let shade = lit.map(|v| v / 3);
        assert!(shaded.density(shade) > 50.0 * plain.density(shade));
        assert!(shaded.density(shade) < shaded.density(lit));
        let lip = [170u8, 80, 85];
        assert!(shaded.density(lip) <= plain.density(lip));
        assert!(shaded.density([255, 250, 235]) <= plain.density([255, 250, 235]));
        let total: f32 = shaded.density.iter().sum();
        assert!((total - BINS as f32).abs() < 1e-2 * BINS as f32);
    }
}
