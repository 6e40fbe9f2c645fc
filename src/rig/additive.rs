//! The rig's three modes as one additive generative model, fitted to the data directly:
//! x̂(d) = b + Σ_i g_i(d_i), each g_i a one-input tanh network `[1, h, 6]` (the generation
//! half of a one-component NLPCA). It is trained as an inverse NLPCA (Scholz et al. 2005,
//! "Non-linear PCA: a missing data approach"): the networks' weights and every training
//! pose's parameters are optimised together (L-BFGS), so the model minimises the error of the
//! sum Φ1(d1) + Φ2(d2) + Φ3(d3) itself rather than of each part alone.
//!
//! The modes start as straight lines: the first along the data's first principal direction
//! (opening), the other two spanning the next two principal directions, turned so that the
//! second moves the front of the mesh sideways the most (lateral excursion) and the third is
//! the rest (protrusion). Training then bends them.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::Progress;

pub const MODES: usize = 3;

/// One mode: d ↦ W4·tanh(W3·d + b3).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ModeNet {
    pub w3: Vec<f64>,
    pub b3: Vec<f64>,
    /// Row-major, `dims × hidden`.
    pub w4: Vec<f64>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct AdditiveModes {
    pub dims: usize,
    pub hidden: usize,
    pub bias: Vec<f64>,
    pub modes: Vec<ModeNet>,
}

impl ModeNet {
    fn add_to(&self, d: f64, dims: usize, out: &mut [f64]) {
        let h = self.w3.len();
        for j in 0..h {
            let a = (self.w3[j] * d + self.b3[j]).tanh();
            for (q, o) in out.iter_mut().enumerate().take(dims) {
                *o += self.w4[q * h + j] * a;
            }
        }
    }
}

impl AdditiveModes {
    /// x̂(d).
    pub fn generate(&self, d: &[f64; MODES]) -> Vec<f64> {
        let mut out = self.bias.clone();
        for (m, &di) in self.modes.iter().zip(d) {
            m.add_to(di, self.dims, &mut out);
        }
        out
    }

    /// Mode `k` alone at `d` (without the bias).
    pub fn mode(&self, k: usize, d: f64) -> Vec<f64> {
        let mut out = vec![0.0; self.dims];
        self.modes[k].add_to(d, self.dims, &mut out);
        out
    }

    pub fn check(&self) -> Result<(), String> {
        if self.modes.len() != MODES || self.bias.len() != self.dims {
            return Err(format!(
                "expected {MODES} modes and {} bias values",
                self.dims
            ));
        }
        for (k, m) in self.modes.iter().enumerate() {
            if m.w3.len() != self.hidden
                || m.b3.len() != self.hidden
                || m.w4.len() != self.hidden * self.dims
            {
                return Err(format!(
                    "modes[{k}]: weights do not match hidden = {}",
                    self.hidden
                ));
            }
            if m.w3
                .iter()
                .chain(&m.b3)
                .chain(&m.w4)
                .any(|v| !v.is_finite())
            {
                return Err(format!("modes[{k}]: a weight is not a finite number"));
            }
        }
        Ok(())
    }
}

/// Settings of the fit.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct AdditiveSettings {
    /// Hidden tanh units per mode.
    pub hidden: usize,
    pub max_iterations: u64,
    pub memory: usize,
    /// ν · mean(w²) over the weights (not the biases or the parameters).
    pub weight_decay: f64,
    pub seed: u64,
}

impl Default for AdditiveSettings {
    fn default() -> Self {
        AdditiveSettings {
            hidden: 6,
            max_iterations: 3000,
            memory: 10,
            weight_decay: 1e-7,
            seed: 0,
        }
    }
}

impl AdditiveSettings {
    /// Every field in its range (see [`crate::settings`]).
    pub fn validate(&self, rules: &crate::settings::Rules) -> crate::error::Result<()> {
        rules.count("hidden", self.hidden as u64, 1, 1024)?;
        rules.count("max_iterations", self.max_iterations, 0, 10_000_000)?;
        rules.count("memory", self.memory as u64, 1, 1000)?;
        rules.number("weight_decay", self.weight_decay, 0.0, 1e3)?;
        Ok(())
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AdditiveReport {
    pub iterations: u64,
    /// Share of the variance unexplained at the start and at the end.
    pub unexplained_initial: f64,
    pub unexplained: f64,
    pub seconds: f64,
}

/// Layout of the optimised vector: per mode W3 (h), b3 (h), W4 (dims·h); the bias (dims);
/// then the parameters of every sample (n·3).
#[derive(Clone, Copy)]
pub(super) struct Layout {
    pub dims: usize,
    pub h: usize,
    pub n: usize,
}

impl Layout {
    fn mode_len(&self) -> usize {
        self.h * (2 + self.dims)
    }
    pub(super) fn bias_at(&self) -> usize {
        MODES * self.mode_len()
    }
    pub(super) fn params_at(&self) -> usize {
        self.bias_at() + self.dims
    }
    pub(super) fn len(&self) -> usize {
        self.params_at() + self.n * MODES
    }
    fn is_weight(&self, i: usize) -> bool {
        i < self.bias_at() && {
            let r = i % self.mode_len();
            r < self.h || r >= 2 * self.h
        }
    }
    /// Every sample's parameters.
    pub(super) fn params(&self, theta: &[f64]) -> Vec<[f64; MODES]> {
        (0..self.n)
            .map(|n| std::array::from_fn(|k| theta[self.params_at() + n * MODES + k]))
            .collect()
    }

    pub(super) fn unpack(&self, theta: &[f64]) -> AdditiveModes {
        let modes = (0..MODES)
            .map(|k| {
                let m = &theta[k * self.mode_len()..(k + 1) * self.mode_len()];
                ModeNet {
                    w3: m[..self.h].to_vec(),
                    b3: m[self.h..2 * self.h].to_vec(),
                    w4: m[2 * self.h..].to_vec(),
                }
            })
            .collect();
        AdditiveModes {
            dims: self.dims,
            hidden: self.h,
            bias: theta[self.bias_at()..self.params_at()].to_vec(),
            modes,
        }
    }
}

impl Layout {
    /// x̂ for sample `n` into `e` (bias plus every mode), keeping the modes' hidden activations
    /// in `a` (`MODES × h`) for [`Layout::backward`].
    pub(super) fn forward(&self, theta: &[f64], n: usize, e: &mut [f64], a: &mut [f64]) {
        let ml = self.mode_len();
        let d = &theta[self.params_at() + n * MODES..self.params_at() + (n + 1) * MODES];
        e.copy_from_slice(&theta[self.bias_at()..self.params_at()]);
        for k in 0..MODES {
            let m = &theta[k * ml..(k + 1) * ml];
            for j in 0..self.h {
                let aj = (m[j] * d[k] + m[self.h + j]).tanh();
                a[k * self.h + j] = aj;
                for q in 0..self.dims {
                    e[q] += m[2 * self.h + q * self.h + j] * aj;
                }
            }
        }
    }

    /// Add to `g` the gradient of sample `n`'s error, given ∂error/∂x̂ = `dy` and the
    /// activations of [`Layout::forward`].
    pub(super) fn backward(&self, theta: &[f64], n: usize, dy: &[f64], a: &[f64], g: &mut [f64]) {
        let ml = self.mode_len();
        let d = &theta[self.params_at() + n * MODES..self.params_at() + (n + 1) * MODES];
        for q in 0..self.dims {
            g[self.bias_at() + q] += dy[q];
        }
        for k in 0..MODES {
            let m = &theta[k * ml..(k + 1) * ml];
            let mut gd = 0.0;
            for j in 0..self.h {
                let aj = a[k * self.h + j];
                let mut da = 0.0;
                for q in 0..self.dims {
                    g[k * ml + 2 * self.h + q * self.h + j] += dy[q] * aj;
                    da += m[2 * self.h + q * self.h + j] * dy[q];
                }
                let dz = da * (1.0 - aj * aj);
                g[k * ml + j] += dz * d[k];
                g[k * ml + self.h + j] += dz;
                gd += dz * m[j];
            }
            g[self.params_at() + n * MODES + k] += gd;
        }
    }

    /// Add the weight decay ν · mean(w²) over the modes' weights to `err` and `g`.
    pub(super) fn decay(&self, theta: &[f64], decay: f64, err: &mut f64, g: &mut [f64]) {
        let count = (0..self.bias_at())
            .filter(|&i| self.is_weight(i))
            .count()
            .max(1) as f64;
        for i in 0..self.bias_at() {
            if self.is_weight(i) {
                *err += decay * theta[i] * theta[i] / count;
                g[i] += 2.0 * decay * theta[i] / count;
            }
        }
    }
}

fn error_and_gradient(l: Layout, theta: &[f64], data: &[f64], decay: f64) -> (f64, Vec<f64>) {
    let variance: f64 = data.iter().map(|v| v * v).sum::<f64>().max(1e-300);
    let norm = 1.0 / variance;
    let (mut err, mut g) = over_samples(l.n, theta.len(), |samples, err, g| {
        let mut a = vec![0.0; MODES * l.h];
        let mut e = vec![0.0; l.dims];
        for n in samples {
            let x = &data[n * l.dims..(n + 1) * l.dims];
            l.forward(theta, n, &mut e, &mut a);
            for q in 0..l.dims {
                e[q] -= x[q];
                *err += e[q] * e[q] * norm;
                e[q] *= 2.0 * norm;
            }
            l.backward(theta, n, &e, &a, g);
        }
    });
    l.decay(theta, decay, &mut err, &mut g);
    (err, g)
}

/// The error and gradient summed over `n` samples, in parallel blocks: `add(samples, err, g)`
/// adds the block's share to `err` and `g` (of `len` values).
pub(super) fn over_samples(
    n: usize,
    len: usize,
    add: impl Fn(std::ops::Range<usize>, &mut f64, &mut [f64]) + Sync,
) -> (f64, Vec<f64>) {
    use rayon::prelude::*;
    // Blocks big enough that a thread's work outweighs adding one more gradient vector.
    const BLOCK: usize = 128;
    // Collected in order and summed in order, so the result does not depend on how the
    // threads shared the blocks: training stays deterministic.
    let blocks: Vec<(f64, Vec<f64>)> = (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let (mut err, mut g) = (0.0, vec![0.0; len]);
            add(b * BLOCK..((b + 1) * BLOCK).min(n), &mut err, &mut g);
            (err, g)
        })
        .collect();
    let (mut err, mut g) = (0.0, vec![0.0; len]);
    for (e, gb) in blocks {
        err += e;
        g.iter_mut().zip(&gb).for_each(|(a, b)| *a += b);
    }
    (err, g)
}

/// Fit the modes to `data` (centred, n×dims row-major), starting from the straight modes
/// along the orthonormal `directions`. Returns the modes and every sample's parameters.
pub fn fit(
    data: &[f64],
    dims: usize,
    directions: &[Vec<f64>; MODES],
    settings: &AdditiveSettings,
    progress: &Progress,
) -> (AdditiveModes, Vec<[f64; MODES]>, AdditiveReport) {
    let (l, theta, report) = fit_vector(data, dims, directions, settings, progress);
    (l.unpack(&theta), l.params(&theta), report)
}

/// [`fit`], returning the optimised vector and its layout (the coupled fit goes on from it).
pub(super) fn fit_vector(
    data: &[f64],
    dims: usize,
    directions: &[Vec<f64>; MODES],
    settings: &AdditiveSettings,
    progress: &Progress,
) -> (Layout, Vec<f64>, AdditiveReport) {
    const GAIN: f64 = 3.0;
    let started = std::time::Instant::now();
    let h = settings.hidden.max(1);
    let l = Layout {
        dims,
        h,
        n: data.len() / dims,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let mut theta = vec![0.0; l.len()];
    let ml = l.mode_len();
    for (k, u) in directions.iter().enumerate() {
        let m = &mut theta[k * ml..(k + 1) * ml];
        for v in m.iter_mut() {
            *v = rng.random_range(-0.3..0.3);
        }
        // Hidden unit 0 carries the line d ↦ u·d, through tanh at a gain where it already
        // bends (from a nearly linear start, training stays at the linear solution: a saddle).
        m[0] = GAIN;
        m[h] = 0.0;
        for q in 0..dims {
            m[2 * h + q * h] = u[q] / GAIN;
        }
    }
    for (n, x) in data.chunks_exact(dims).enumerate() {
        for (k, u) in directions.iter().enumerate() {
            theta[l.params_at() + n * MODES + k] = u.iter().zip(x).map(|(a, b)| a * b).sum();
        }
    }
    let unexplained_of = |t: &[f64]| error_and_gradient(l, t, data, 0.0).0;
    let unexplained_initial = unexplained_of(&theta);
    let f = reporting(
        |t: &[f64]| error_and_gradient(l, t, data, settings.weight_decay),
        "the three modes",
        progress,
    );
    let (theta, _, iterations) =
        super::lbfgs::minimise(&f, theta, settings.max_iterations, settings.memory);
    let report = AdditiveReport {
        iterations,
        unexplained_initial,
        unexplained: unexplained_of(&theta),
        seconds: started.elapsed().as_secs_f64(),
    };
    (l, theta, report)
}

/// `f`, telling `progress` every so many evaluations how far the fit of `what` is.
pub(super) fn reporting<'a>(
    f: impl Fn(&[f64]) -> (f64, Vec<f64>) + Sync + 'a,
    what: &'a str,
    progress: &'a Progress,
) -> impl Fn(&[f64]) -> (f64, Vec<f64>) + Sync + 'a {
    let count = std::sync::atomic::AtomicU64::new(0);
    move |t| {
        let (e, g) = f(t);
        let n = count.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if n.is_multiple_of(50) {
            progress(&format!("{what}: {n} evaluations, error {e:.3e}"));
        }
        (e, g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_finite_differences() {
        let l = Layout {
            dims: 4,
            h: 3,
            n: 5,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let theta: Vec<f64> = (0..l.len()).map(|_| rng.random_range(-0.5..0.5)).collect();
        let data: Vec<f64> = (0..l.n * l.dims)
            .map(|_| rng.random_range(-0.2..0.2))
            .collect();
        crate::rig::assert_gradient_matches_differences(&theta, |t| {
            error_and_gradient(l, t, &data, 1e-2)
        });
    }

    #[test]
    fn bends_a_straight_mode_into_a_curve() {
        // One curved mode (a parabola in the plane of the first two coordinates) plus a
        // straight one; the third direction is unused.
        let mut data = Vec::new();
        for i in 0..15 {
            for j in 0..5 {
                let t = -0.2 + 0.4 * i as f64 / 14.0;
                let s = -0.05 + 0.1 * j as f64 / 4.0;
                data.extend([t, 2.0 * t * t - 0.03, s, 0.0]);
            }
        }
        let dirs = [
            vec![1.0, 0.0, 0.0, 0.0],
            vec![0.0, 0.0, 1.0, 0.0],
            vec![0.0, 0.0, 0.0, 1.0],
        ];
        let (modes, params, report) = fit(&data, 4, &dirs, &AdditiveSettings::default(), &|_| {});
        assert!(report.unexplained_initial > 0.02, "{report:?}");
        assert!(
            report.unexplained < 0.1 * report.unexplained_initial,
            "{report:?}"
        );
        let x = modes.generate(&params[37]);
        assert!((x[1] - data[37 * 4 + 1]).abs() < 0.01, "{x:?}");
    }
}
