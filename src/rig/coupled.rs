//! Couplings between the rig's modes: Φ(d) = Σ_i Φi(d_i) + Σ_{i<j} Gij(d_i, d_j).
//!
//! The paper's sum (Eq. 5) moves the jaw the same way sideways whether the mouth is closed or
//! open; a real joint does not (the condyles sit elsewhere on the eminence, the Bennett shift
//! and the guidance act differently), and on such motion the sum errs where two modes act at
//! once. Each coupling Gij is a small two-input tanh network H taken as
//! Gij(a, b) = H(a, b) − H(a, 0) − H(0, b) + H(0, 0), which vanishes whenever either
//! parameter is zero: with the others at zero, each d_i still moves the jaw along its own mode
//! Φi alone, so the parameters keep their meaning (opening, lateral excursion, protrusion) and
//! the modes' gains and ranges are built as for the sum.
//!
//! Fitted after the sum, from it (the couplings' outputs start at zero), as one inverse NLPCA:
//! the modes, the couplings and every pose's parameters together.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::Progress;
use super::additive::{self, AdditiveModes, AdditiveReport, AdditiveSettings, Layout, MODES};

/// The pairs of modes coupled: opening with lateral, opening with protrusion, lateral with
/// protrusion.
pub const PAIRS: [[usize; 2]; 3] = [[0, 1], [0, 2], [1, 2]];

/// One coupling: H(a, b) = W2·tanh(W1·(a, b) + b1).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Coupling {
    /// The two modes, indices into (opening, lateral, protrusion).
    pub modes: [usize; 2],
    /// Row-major, `hidden × 2`.
    pub w1: Vec<f64>,
    pub b1: Vec<f64>,
    /// Row-major, `dims × hidden`.
    pub w2: Vec<f64>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Couplings {
    pub dims: usize,
    pub hidden: usize,
    pub pairs: Vec<Coupling>,
}

impl Coupling {
    /// The activations at (a, b), (a, 0), (0, b) and (0, 0) combined as G takes them.
    fn combined(&self, a: f64, b: f64, j: usize) -> f64 {
        let (wa, wb, c) = (self.w1[2 * j], self.w1[2 * j + 1], self.b1[j]);
        (wa * a + wb * b + c).tanh() - (wa * a + c).tanh() - (wb * b + c).tanh() + c.tanh()
    }
}

impl Couplings {
    /// Add Σ Gij(d_i, d_j) to `out`.
    pub fn add_to(&self, d: &[f64; MODES], out: &mut [f64]) {
        for p in &self.pairs {
            let (a, b) = (d[p.modes[0]], d[p.modes[1]]);
            for j in 0..self.hidden {
                let c = p.combined(a, b, j);
                for (q, o) in out.iter_mut().enumerate().take(self.dims) {
                    *o += p.w2[q * self.hidden + j] * c;
                }
            }
        }
    }

    pub fn check(&self) -> Result<(), String> {
        for (k, p) in self.pairs.iter().enumerate() {
            if p.modes[0] >= MODES || p.modes[1] >= MODES || p.modes[0] == p.modes[1] {
                return Err(format!(
                    "pairs[{k}].modes: two different modes below {MODES}"
                ));
            }
            if p.w1.len() != 2 * self.hidden
                || p.b1.len() != self.hidden
                || p.w2.len() != self.dims * self.hidden
            {
                return Err(format!(
                    "pairs[{k}]: weights do not match hidden = {} and dims = {}",
                    self.hidden, self.dims
                ));
            }
            if p.w1
                .iter()
                .chain(&p.b1)
                .chain(&p.w2)
                .any(|v| !v.is_finite())
            {
                return Err(format!("pairs[{k}]: a weight is not a finite number"));
            }
        }
        Ok(())
    }
}

/// The couplings' settings: those of the modes' fit (hidden units per coupling, iterations,
/// memory, weight decay over the couplings' and the modes' weights, seed), with fewer hidden
/// units by default.
pub fn default_settings() -> AdditiveSettings {
    AdditiveSettings {
        hidden: 4,
        ..Default::default()
    }
}

/// Where the couplings sit in the optimised vector: after the additive model's own layout
/// (modes, bias, parameters), per pair W1 (2h), b1 (h), W2 (dims·h).
#[derive(Clone, Copy)]
struct Coupled {
    base: Layout,
    h: usize,
}

impl Coupled {
    fn pair_len(&self) -> usize {
        self.h * (3 + self.base.dims)
    }
    fn pair_at(&self, p: usize) -> usize {
        self.base.len() + p * self.pair_len()
    }
    fn len(&self) -> usize {
        self.pair_at(PAIRS.len())
    }

    fn unpack(&self, theta: &[f64]) -> Couplings {
        let h = self.h;
        let pairs = PAIRS
            .iter()
            .enumerate()
            .map(|(p, modes)| {
                let w = &theta[self.pair_at(p)..self.pair_at(p) + self.pair_len()];
                Coupling {
                    modes: *modes,
                    w1: w[..2 * h].to_vec(),
                    b1: w[2 * h..3 * h].to_vec(),
                    w2: w[3 * h..].to_vec(),
                }
            })
            .collect();
        Couplings {
            dims: self.base.dims,
            hidden: h,
            pairs,
        }
    }

    fn error_and_gradient(&self, theta: &[f64], data: &[f64], decay: f64) -> (f64, Vec<f64>) {
        let (l, h, dims) = (self.base, self.h, self.base.dims);
        let variance: f64 = data.iter().map(|v| v * v).sum::<f64>().max(1e-300);
        let norm = 1.0 / variance;
        let t0: Vec<f64> = (0..PAIRS.len() * h)
            .map(|i| theta[self.pair_at(i / h) + 2 * h + i % h].tanh())
            .collect();
        let (mut err, mut g) = additive::over_samples(l.n, theta.len(), |samples, err, g| {
            let mut a = vec![0.0; MODES * l.h];
            let mut e = vec![0.0; dims];
            // Per pair and hidden unit: tanh at (a, b), (a, 0), (0, b); (0, 0) is per unit only.
            let mut t = vec![[0.0; 3]; PAIRS.len() * h];
            for n in samples {
                let x = &data[n * dims..(n + 1) * dims];
                l.forward(theta, n, &mut e, &mut a);
                let d = &theta[l.params_at() + n * MODES..l.params_at() + (n + 1) * MODES];
                for (p, [i, k]) in PAIRS.iter().enumerate() {
                    let w = &theta[self.pair_at(p)..self.pair_at(p) + self.pair_len()];
                    let (u, v) = (d[*i], d[*k]);
                    for j in 0..h {
                        let (wa, wb, c) = (w[2 * j], w[2 * j + 1], w[2 * h + j]);
                        let tt = [
                            (wa * u + wb * v + c).tanh(),
                            (wa * u + c).tanh(),
                            (wb * v + c).tanh(),
                        ];
                        t[p * h + j] = tt;
                        let comb = tt[0] - tt[1] - tt[2] + t0[p * h + j];
                        for q in 0..dims {
                            e[q] += w[3 * h + q * h + j] * comb;
                        }
                    }
                }
                for q in 0..dims {
                    e[q] -= x[q];
                    *err += e[q] * e[q] * norm;
                    e[q] *= 2.0 * norm;
                }
                l.backward(theta, n, &e, &a, g);
                for (p, [i, k]) in PAIRS.iter().enumerate() {
                    let at = self.pair_at(p);
                    let (u, v) = (d[*i], d[*k]);
                    let (mut gu, mut gv) = (0.0, 0.0);
                    for j in 0..h {
                        let (wa, wb) = (theta[at + 2 * j], theta[at + 2 * j + 1]);
                        let tt = t[p * h + j];
                        let t00 = t0[p * h + j];
                        let comb = tt[0] - tt[1] - tt[2] + t00;
                        let mut da = 0.0;
                        for (q, eq) in e.iter().enumerate() {
                            let w2 = at + 3 * h + q * h + j;
                            g[w2] += eq * comb;
                            da += theta[w2] * eq;
                        }
                        let dz = [
                            da * (1.0 - tt[0] * tt[0]),
                            -da * (1.0 - tt[1] * tt[1]),
                            -da * (1.0 - tt[2] * tt[2]),
                        ];
                        let dz0 = da * (1.0 - t00 * t00);
                        g[at + 2 * j] += (dz[0] + dz[1]) * u;
                        g[at + 2 * j + 1] += (dz[0] + dz[2]) * v;
                        g[at + 2 * h + j] += dz[0] + dz[1] + dz[2] + dz0;
                        gu += (dz[0] + dz[1]) * wa;
                        gv += (dz[0] + dz[2]) * wb;
                    }
                    g[l.params_at() + n * MODES + i] += gu;
                    g[l.params_at() + n * MODES + k] += gv;
                }
            }
        });
        l.decay(theta, decay, &mut err, &mut g);
        // The couplings' weights (W1 and W2, not b1) decay with the same ν.
        let weights = |p: usize| {
            let at = self.pair_at(p);
            (at..at + 2 * h).chain(at + 3 * h..at + self.pair_len())
        };
        let count = (PAIRS.len() * h * (2 + dims)) as f64;
        for p in 0..PAIRS.len() {
            for i in weights(p) {
                err += decay * theta[i] * theta[i] / count;
                g[i] += 2.0 * decay * theta[i] / count;
            }
        }
        (err, g)
    }
}

/// Fit the modes and their couplings to `data` (centred, n×dims row-major), from the additive
/// model already fitted (`base` and `theta`, from [`additive::fit_vector`]).
pub(super) fn fit(
    data: &[f64],
    base: Layout,
    theta: Vec<f64>,
    settings: &AdditiveSettings,
    progress: &Progress,
) -> (AdditiveModes, Couplings, Vec<[f64; MODES]>, AdditiveReport) {
    let started = std::time::Instant::now();
    let c = Coupled {
        base,
        h: settings.hidden.max(1),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed ^ 0xC0_0C1E);
    let mut full = theta;
    full.resize(c.len(), 0.0);
    for p in 0..PAIRS.len() {
        let at = c.pair_at(p);
        // Input weights of order 1/(the parameters' spread, ~0.1) so that tanh bends across
        // the data; outputs zero, so the fit starts exactly at the additive model.
        for v in &mut full[at..at + 2 * c.h] {
            *v = rng.random_range(-8.0..8.0);
        }
        for v in &mut full[at + 2 * c.h..at + 3 * c.h] {
            *v = rng.random_range(-0.5..0.5);
        }
    }
    let unexplained_of = |t: &[f64]| c.error_and_gradient(t, data, 0.0).0;
    let unexplained_initial = unexplained_of(&full);
    let f = additive::reporting(
        |t: &[f64]| c.error_and_gradient(t, data, settings.weight_decay),
        "the modes' couplings",
        progress,
    );
    let (full, _, iterations) =
        super::lbfgs::minimise(&f, full, settings.max_iterations, settings.memory);
    let report = AdditiveReport {
        iterations,
        unexplained_initial,
        unexplained: unexplained_of(&full),
        seconds: started.elapsed().as_secs_f64(),
    };
    (
        base.unpack(&full),
        c.unpack(&full),
        base.params(&full),
        report,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_finite_differences() {
        let c = Coupled {
            base: Layout {
                dims: 4,
                h: 3,
                n: 5,
            },
            h: 2,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let theta: Vec<f64> = (0..c.len()).map(|_| rng.random_range(-0.8..0.8)).collect();
        let data: Vec<f64> = (0..c.base.n * c.base.dims)
            .map(|_| rng.random_range(-0.2..0.2))
            .collect();
        crate::rig::assert_gradient_matches_differences(&theta, |t| {
            c.error_and_gradient(t, &data, 1e-2)
        });
    }

    #[test]
    fn a_coupling_vanishes_where_either_parameter_is_zero() {
        let c = Coupled {
            base: Layout {
                dims: 3,
                h: 2,
                n: 0,
            },
            h: 3,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let theta: Vec<f64> = (0..c.len()).map(|_| rng.random_range(-2.0..2.0)).collect();
        let couplings = c.unpack(&theta);
        for d in [[0.3, 0.0, 0.0], [0.0, -0.2, 0.0], [0.0, 0.0, 0.1]] {
            let mut out = vec![0.0; 3];
            couplings.add_to(&d, &mut out);
            assert!(out.iter().all(|v| v.abs() < 1e-12), "{d:?}: {out:?}");
        }
        let mut out = vec![0.0; 3];
        couplings.add_to(&[0.3, -0.2, 0.1], &mut out);
        assert!(out.iter().any(|v| v.abs() > 1e-3), "{out:?}");
    }

    #[test]
    fn learns_how_the_modes_bend_each_other() {
        // x = (a, b, c, ab, ac, bc): three modes hold a, b and c, and their sum cannot hold
        // the products.
        let mut data = Vec::new();
        let at = |i: usize| -0.2 + 0.4 * i as f64 / 5.0;
        for i in 0..6 {
            for j in 0..6 {
                for k in 0..6 {
                    let (a, b, c) = (at(i), at(j), at(k));
                    data.extend([a, b, c, 3.0 * a * b, 3.0 * a * c, 3.0 * b * c]);
                }
            }
        }
        let dirs: [Vec<f64>; 3] =
            std::array::from_fn(|k| (0..6).map(|q| if q == k { 1.0 } else { 0.0 }).collect());
        let settings = additive::AdditiveSettings::default();
        let (base, theta, sum) = additive::fit_vector(&data, 6, &dirs, &settings, &|_| {});
        let (_, _, _, coupled) = fit(&data, base, theta, &default_settings(), &|_| {});
        assert!(
            coupled.unexplained < 0.1 * sum.unexplained,
            "sum {sum:?}, coupled {coupled:?}"
        );
    }
}
