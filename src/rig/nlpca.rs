//! Hierarchical nonlinear PCA (Scholz & Vigário 2002, the paper's refs [8], [36]): an
//! autoencoder `[d, h, k, h, d]` with tanh hidden layers and a linear component layer, trained
//! on the hierarchical error: the sum, over i = 1..k, of the reconstruction error of the
//! sub-network that uses components 1..i only (the others set to zero). That gives the
//! components an order, as in PCA: the first explains the most.
//!
//! The gradient is back-propagated by hand (and checked against finite differences in the
//! tests); the optimiser is argmin's L-BFGS with a Moré-Thuente line search.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::network::{Shape, error_and_gradient};

/// Training settings. The defaults are what the rig uses.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct NlpcaSettings {
    /// Units in each tanh hidden layer.
    pub hidden: usize,
    /// Weight decay ν: the error gets ν · mean(w²) over the weights (not the biases).
    pub weight_decay: f64,
    /// L-BFGS iterations at most.
    pub max_iterations: u64,
    /// L-BFGS memory (correction pairs).
    pub memory: usize,
    /// Seed of the initial weights: the same seed and data give the same network.
    pub seed: u64,
    /// Input scaling: the data are centred and scaled so that the largest standard deviation
    /// of a coordinate is this (Scholz's NLPCA uses 0.1: the tanh units start near linear).
    pub input_std: f64,
}

impl Default for NlpcaSettings {
    fn default() -> Self {
        NlpcaSettings {
            hidden: 10,
            weight_decay: 1e-6,
            max_iterations: 3000,
            memory: 10,
            seed: 0,
            input_std: 0.1,
        }
    }
}

impl NlpcaSettings {
    /// Every field in its range (see [`crate::settings`]).
    pub fn validate(&self, rules: &crate::settings::Rules) -> crate::error::Result<()> {
        rules.count("hidden", self.hidden as u64, 1, 1024)?;
        rules.number("weight_decay", self.weight_decay, 0.0, 1e3)?;
        rules.count("max_iterations", self.max_iterations, 0, 10_000_000)?;
        rules.count("memory", self.memory as u64, 1, 1000)?;
        rules.above("input_std", self.input_std, 0.0, 100.0)?;
        Ok(())
    }
}

/// A trained network. Inputs and outputs are in the caller's units; the scaling is inside.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Nlpca {
    pub inputs: usize,
    pub hidden: usize,
    pub components: usize,
    /// Input scaling: `x_n = (x − mean) · scale`.
    pub mean: Vec<f64>,
    pub scale: f64,
    /// W1 (h×d), b1, W2 (k×h), b2, W3 (h×k), b3, W4 (d×h), b4, row-major.
    pub weights: Vec<f64>,
}

/// What training did.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrainReport {
    pub iterations: u64,
    /// The hierarchical error at the end: the mean over sub-networks of the share of the
    /// variance each leaves unexplained relative to PCA's with as many components (1 = as
    /// good as PCA), plus weight decay.
    pub error: f64,
    /// Share of the variance left unexplained by the sub-network with components 1..i.
    pub unexplained: Vec<f64>,
    pub seconds: f64,
}

/// Why training could not run.
#[derive(Debug, thiserror::Error)]
pub enum NlpcaError {
    #[error("NLPCA needs at least {need} samples, got {got}")]
    TooFewSamples { need: usize, got: usize },
    #[error("NLPCA: the data do not vary (all samples are the same)")]
    NoVariance,
    #[error("NLPCA: {components} components for {inputs}-dimensional data")]
    BadShape { inputs: usize, components: usize },
}

/// The samples' mean and the largest standard deviation of any coordinate (over n, not n − 1):
/// the input scaling takes the widest coordinate to a standard deviation of 0.1.
pub(super) fn mean_and_widest_std(samples: &[Vec<f64>]) -> (Vec<f64>, f64) {
    let d = samples.first().map_or(0, Vec::len);
    let n = samples.len().max(1) as f64;
    let mean: Vec<f64> = (0..d)
        .map(|q| samples.iter().map(|s| s[q]).sum::<f64>() / n)
        .collect();
    let max_std = (0..d)
        .map(|q| {
            (samples
                .iter()
                .map(|s| (s[q] - mean[q]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        })
        .fold(0.0, f64::max);
    (mean, max_std)
}

impl Nlpca {
    fn shape(&self) -> Shape {
        Shape {
            d: self.inputs,
            h: self.hidden,
            k: self.components,
        }
    }

    /// Train on `samples` (each `inputs` long) with `components` components.
    pub fn train(
        samples: &[Vec<f64>],
        components: usize,
        settings: &NlpcaSettings,
    ) -> Result<(Nlpca, TrainReport), NlpcaError> {
        let started = std::time::Instant::now();
        let d = samples.first().map_or(0, Vec::len);
        if components == 0 || components > d || settings.hidden == 0 {
            return Err(NlpcaError::BadShape {
                inputs: d,
                components,
            });
        }
        let need = components + 2;
        if samples.len() < need {
            return Err(NlpcaError::TooFewSamples {
                need,
                got: samples.len(),
            });
        }
        let (mean, max_std) = mean_and_widest_std(samples);
        if max_std <= 1e-12 {
            return Err(NlpcaError::NoVariance);
        }
        let scale = settings.input_std / max_std;
        let data: Vec<f64> = samples
            .iter()
            .flat_map(|s| s.iter().zip(&mean).map(|(v, m)| (v - m) * scale))
            .collect();
        let shape = Shape {
            d,
            h: settings.hidden,
            k: components,
        };
        // Linear PCA of the scaled data: the starting point (each sub-network starts as PCA
        // with as many components) and the balance of the hierarchical error (each
        // sub-network's error is counted relative to PCA's with as many components, so the
        // last components are not drowned by the first ones' much larger errors).
        let (basis, unexplained_pca) = pca_basis(&data, d);
        let balance: Vec<f64> = unexplained_pca[..components]
            .iter()
            .map(|u| 1.0 / u.max(BALANCE_FLOOR))
            .collect();
        // The start is PCA: hidden units 1..k carry the principal components through the
        // near-linear middle of tanh, so every sub-network starts as PCA with as many
        // components, and L-BFGS only goes down from there: NLPCA is never worse than PCA.
        // The other hidden units start as random curved features of their inputs (large input
        // weights, zero output weights): the output is still PCA's, but the gradient sees at
        // once how those features would explain what PCA leaves. (With those units near zero
        // instead, the start is a saddle that training hardly leaves.)
        let f = |w: &[f64]| error_and_gradient(shape, w, &data, &balance, settings.weight_decay);
        let start = initial_weights(shape, settings.seed, Some(&basis));
        let (weights, best, iterations) =
            super::lbfgs::minimise(&f, start, settings.max_iterations, settings.memory);
        let net = Nlpca {
            inputs: d,
            hidden: settings.hidden,
            components,
            mean,
            scale,
            weights,
        };
        let unexplained = net.unexplained(&data);
        Ok((
            net,
            TrainReport {
                iterations,
                error: best,
                unexplained,
                seconds: started.elapsed().as_secs_f64(),
            },
        ))
    }
}

/// The smallest unexplained share a sub-network's error is divided by.
const BALANCE_FLOOR: f64 = 1e-6;

/// Principal directions of centred data (n×d row-major), largest first, and the share of the
/// variance left unexplained by the first 1..d of them.
fn pca_basis(data: &[f64], d: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
    let mut cov = nalgebra::DMatrix::<f64>::zeros(d, d);
    for x in data.chunks_exact(d) {
        for i in 0..d {
            for j in 0..d {
                cov[(i, j)] += x[i] * x[j];
            }
        }
    }
    let eig = nalgebra::SymmetricEigen::new(cov);
    let mut order: Vec<usize> = (0..d).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let total: f64 = eig
        .eigenvalues
        .iter()
        .map(|v| v.max(0.0))
        .sum::<f64>()
        .max(1e-300);
    let mut left = total;
    let mut unexplained = Vec::with_capacity(d);
    for &j in &order {
        left -= eig.eigenvalues[j].max(0.0);
        unexplained.push((left / total).max(0.0));
    }
    let basis = order
        .iter()
        .map(|&j| eig.eigenvectors.column(j).iter().copied().collect())
        .collect();
    (basis, unexplained)
}

/// Initial weights from the seed. With a PCA basis (and h ≥ k), sub-network i starts as PCA
/// with i components: hidden unit j < k carries principal component j through the near-linear
/// middle of tanh (gain 0.1); the other hidden units get large random input weights (curved
/// features) and zero output weights; the remaining weights are small random numbers that
/// break the symmetry. Without a basis: Glorot-uniform weights, zero biases.
fn initial_weights(s: Shape, seed: u64, basis: Option<&[Vec<f64>]>) -> Vec<f64> {
    const GAIN: f64 = 0.1;
    const SMALL: f64 = 0.01;
    const CURVED: f64 = 10.0;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let o = s.offsets();
    let fans = [
        (s.d, s.h),
        (0, 0),
        (s.h, s.k),
        (0, 0),
        (s.k, s.h),
        (0, 0),
        (s.h, s.d),
        (0, 0),
    ];
    let from_pca = basis.filter(|b| s.h >= s.k && b.len() >= s.k);
    let mut w = vec![0.0; s.len()];
    for (block, &(fan_in, fan_out)) in fans.iter().enumerate() {
        if fan_in == 0 {
            continue;
        }
        let a =
            (6.0 / (fan_in + fan_out) as f64).sqrt() * if from_pca.is_some() { SMALL } else { 1.0 };
        for v in &mut w[o[block]..o[block + 1]] {
            *v = rng.random_range(-a..a);
        }
    }
    if let Some(basis) = from_pca {
        for (j, p) in basis.iter().take(s.k).enumerate() {
            for q in 0..s.d {
                w[o[0] + j * s.d + q] = GAIN * p[q]; // W1 row j
                w[o[6] + q * s.h + j] = p[q] / GAIN; // W4 column j
            }
            w[o[2] + j * s.h + j] = 1.0 / GAIN; // W2: component j from hidden unit j
            w[o[4] + j * s.k + j] = GAIN; // W3: hidden unit j from component j
        }
        {
            // Hidden units k..h: inputs of order one (the data's scale is 0.1), so tanh bends;
            // their outputs start at zero so the network still computes PCA.
            let (d, h, k) = (s.d, s.h, s.k);
            for j in k..h {
                for q in 0..d {
                    w[o[0] + j * d + q] = rng.random_range(-CURVED..CURVED);
                }
                w[o[1] + j] = rng.random_range(-1.0..1.0);
                for m in 0..k {
                    w[o[2] + m * h + j] = 0.0;
                    w[o[4] + j * k + m] = rng.random_range(-CURVED..CURVED);
                }
                w[o[5] + j] = rng.random_range(-1.0..1.0);
                for q in 0..d {
                    w[o[6] + q * h + j] = 0.0;
                }
            }
        }
    }
    w
}

impl Nlpca {
    /// Share of the variance of `data` (normalised) unexplained by each sub-network 1..i.
    fn unexplained(&self, data: &[f64]) -> Vec<f64> {
        let s = self.shape();
        let layers = s.layers(&self.weights);
        let variance: f64 = data.iter().map(|v| v * v).sum::<f64>().max(1e-300);
        let mut sse = vec![0.0; s.k];
        let (mut a1, mut c, mut ci) = (vec![0.0; s.h], vec![0.0; s.k], vec![0.0; s.k]);
        let (mut a3, mut y) = (vec![0.0; s.h], vec![0.0; s.d]);
        for x in data.chunks_exact(s.d) {
            layers.encode(s, x, &mut a1, &mut c);
            for i in 1..=s.k {
                ci[..i].copy_from_slice(&c[..i]);
                ci[i..].iter_mut().for_each(|v| *v = 0.0);
                layers.decode(&ci, &mut a3, &mut y);
                sse[i - 1] += y.iter().zip(x).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
            }
        }
        sse.iter().map(|e| e / variance).collect()
    }

    /// The component extraction function Φextr: a sample (caller's units) → its components.
    pub fn extract(&self, x: &[f64]) -> Vec<f64> {
        let s = self.shape();
        let xn: Vec<f64> = x
            .iter()
            .zip(&self.mean)
            .map(|(v, m)| (v - m) * self.scale)
            .collect();
        let (mut a1, mut c) = (vec![0.0; s.h], vec![0.0; s.k]);
        s.layers(&self.weights).encode(s, &xn, &mut a1, &mut c);
        c
    }

    /// The data generation function Φgen: components (missing ones are zero) → a sample in the
    /// caller's units.
    pub fn generate(&self, c: &[f64]) -> Vec<f64> {
        let s = self.shape();
        let mut ck = vec![0.0; s.k];
        for (a, b) in ck.iter_mut().zip(c) {
            *a = *b;
        }
        let (mut a3, mut y) = (vec![0.0; s.h], vec![0.0; s.d]);
        s.layers(&self.weights).decode(&ck, &mut a3, &mut y);
        y.iter()
            .zip(&self.mean)
            .map(|(v, m)| v / self.scale + m)
            .collect()
    }

    /// Rebuild a sample from its first `i` components.
    pub fn reconstruct(&self, x: &[f64], i: usize) -> Vec<f64> {
        let mut c = self.extract(x);
        let keep = i.min(c.len());
        c[keep..].iter_mut().for_each(|v| *v = 0.0);
        self.generate(&c)
    }

    /// Check the stored sizes (a rig file may have been edited).
    pub fn check(&self) -> Result<(), String> {
        let s = self.shape();
        if s.d == 0 || s.h == 0 || s.k == 0 || s.k > s.d {
            return Err(format!("bad shape [{}, {}, {}]", s.d, s.h, s.k));
        }
        if self.weights.len() != s.len() {
            return Err(format!(
                "{} weights for the shape [{d}, {h}, {k}, {h}, {d}], which has {}",
                self.weights.len(),
                s.len(),
                d = s.d,
                h = s.h,
                k = s.k
            ));
        }
        if self.mean.len() != s.d {
            return Err(format!(
                "mean has {} values for {} inputs",
                self.mean.len(),
                s.d
            ));
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(format!(
                "scale must be a positive number, found {}",
                self.scale
            ));
        }
        if let Some(i) = self.weights.iter().position(|w| !w.is_finite()) {
            return Err(format!("weights[{i}] is not a finite number"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(n: usize) -> Vec<Vec<f64>> {
        // A curved one-dimensional set in 3-D, with a little width in a second direction.
        (0..n)
            .map(|i| {
                let t = -1.0 + 2.0 * i as f64 / (n - 1) as f64;
                let u = ((i * 7919) % 13) as f64 / 13.0 - 0.5;
                vec![t, t * t, 0.3 * t.powi(3) + 0.05 * u]
            })
            .collect()
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let s = Shape { d: 3, h: 4, k: 2 };
        let data: Vec<f64> = curve(23).into_iter().flatten().map(|v| v * 0.2).collect();
        let w = initial_weights(s, 7, None);
        let balance = [1.0, 3.0];
        crate::rig::assert_gradient_matches_differences(&w, |w| {
            error_and_gradient(s, w, &data, &balance, 1e-3)
        });
    }

    #[test]
    fn one_component_follows_a_curve_that_pca_cannot() {
        let data = curve(200);
        let settings = NlpcaSettings {
            hidden: 6,
            max_iterations: 1500,
            ..Default::default()
        };
        let (net, report) = Nlpca::train(&data, 2, &settings).unwrap();
        // The curve is one-dimensional up to the small width: one nonlinear component
        // explains nearly all of it (a straight line leaves about 20 %).
        assert!(report.unexplained[0] < 0.02, "{:?}", report.unexplained);
        assert!(report.unexplained[1] <= report.unexplained[0]);
        let x = &data[50];
        let r = net.reconstruct(x, 1);
        assert!((r[1] - x[1]).abs() < 0.1, "{r:?} vs {x:?}");
        // Deterministic.
        let (again, _) = Nlpca::train(&data, 2, &settings).unwrap();
        assert_eq!(net, again);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let s = NlpcaSettings::default();
        assert!(matches!(
            Nlpca::train(&vec![vec![1.0, 2.0]; 10], 1, &s),
            Err(NlpcaError::NoVariance)
        ));
        assert!(matches!(
            Nlpca::train(&curve(3), 2, &s),
            Err(NlpcaError::TooFewSamples { .. })
        ));
        assert!(matches!(
            Nlpca::train(&curve(30), 4, &s),
            Err(NlpcaError::BadShape { .. })
        ));
    }
}
