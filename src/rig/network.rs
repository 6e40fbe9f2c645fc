//! The NLPCA autoencoder's arithmetic: the flat weight vector's layout (`Shape`, `Layers`),
//! the forward pass and the hierarchical error with its back-propagated gradient.

use rayon::prelude::*;

#[derive(Debug, Clone, Copy)]
pub(super) struct Shape {
    pub d: usize,
    pub h: usize,
    pub k: usize,
}

/// Views of the flat weight vector.
pub(super) struct Layers<'a> {
    w1: &'a [f64],
    b1: &'a [f64],
    w2: &'a [f64],
    b2: &'a [f64],
    w3: &'a [f64],
    b3: &'a [f64],
    w4: &'a [f64],
    b4: &'a [f64],
}

impl Shape {
    pub(super) fn sizes(&self) -> [usize; 8] {
        let Shape { d, h, k } = *self;
        [h * d, h, k * h, k, h * k, h, d * h, d]
    }

    pub(super) fn len(&self) -> usize {
        self.sizes().iter().sum()
    }

    /// Offsets of the eight blocks.
    pub(super) fn offsets(&self) -> [usize; 9] {
        let mut o = [0; 9];
        for (i, s) in self.sizes().iter().enumerate() {
            o[i + 1] = o[i] + s;
        }
        o
    }

    pub(super) fn layers<'a>(&self, w: &'a [f64]) -> Layers<'a> {
        let o = self.offsets();
        Layers {
            w1: &w[o[0]..o[1]],
            b1: &w[o[1]..o[2]],
            w2: &w[o[2]..o[3]],
            b2: &w[o[3]..o[4]],
            w3: &w[o[4]..o[5]],
            b3: &w[o[5]..o[6]],
            w4: &w[o[6]..o[7]],
            b4: &w[o[7]..o[8]],
        }
    }

    /// Whether weight `i` is a weight (decayed) rather than a bias.
    pub(super) fn is_weight(&self, i: usize) -> bool {
        let o = self.offsets();
        (o[0]..o[1]).contains(&i)
            || (o[2]..o[3]).contains(&i)
            || (o[4]..o[5]).contains(&i)
            || (o[6]..o[7]).contains(&i)
    }
}

/// `out = W·x + b` for a row-major `W` (rows = out.len()).
pub(super) fn affine(w: &[f64], b: &[f64], x: &[f64], out: &mut [f64]) {
    let n = x.len();
    for (r, o) in out.iter_mut().enumerate() {
        let row = &w[r * n..(r + 1) * n];
        *o = b[r] + row.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
    }
}

impl Layers<'_> {
    pub(super) fn encode(&self, s: Shape, x: &[f64], a1: &mut [f64], c: &mut [f64]) {
        affine(self.w1, self.b1, x, a1);
        a1.iter_mut().for_each(|v| *v = v.tanh());
        affine(self.w2, self.b2, a1, c);
        debug_assert_eq!(c.len(), s.k);
    }

    pub(super) fn decode(&self, c: &[f64], a3: &mut [f64], y: &mut [f64]) {
        affine(self.w3, self.b3, c, a3);
        a3.iter_mut().for_each(|v| *v = v.tanh());
        affine(self.w4, self.b4, a3, y);
    }
}

/// The hierarchical error and its gradient over `data` (normalised, n×d row-major): the mean
/// over sub-networks i = 1..k of `balance[i-1]` times the share of the variance that
/// sub-network leaves unexplained, plus weight decay.
/// Deterministic: fixed chunks, summed in order, whatever the number of threads.
pub(super) fn error_and_gradient(
    s: Shape,
    w: &[f64],
    data: &[f64],
    balance: &[f64],
    decay: f64,
) -> (f64, Vec<f64>) {
    const CHUNK: usize = 64;
    let n = data.len() / s.d;
    let variance: f64 = data.iter().map(|v| v * v).sum::<f64>().max(1e-300);
    let norms: Vec<f64> = balance
        .iter()
        .map(|b| b / (variance * s.k as f64))
        .collect();
    let layers = s.layers(w);
    let o = s.offsets();
    let parts: Vec<(f64, Vec<f64>)> = data
        .par_chunks(CHUNK * s.d)
        .map(|chunk| {
            let mut g = vec![0.0; s.len()];
            let mut err = 0.0;
            let (mut a1, mut c, mut ci) = (vec![0.0; s.h], vec![0.0; s.k], vec![0.0; s.k]);
            let (mut a3, mut y) = (vec![0.0; s.h], vec![0.0; s.d]);
            let (mut dc, mut dz3, mut dz1) = (vec![0.0; s.k], vec![0.0; s.h], vec![0.0; s.h]);
            for x in chunk.chunks_exact(s.d) {
                layers.encode(s, x, &mut a1, &mut c);
                dc.iter_mut().for_each(|v| *v = 0.0);
                for i in 1..=s.k {
                    let norm = norms[i - 1];
                    ci[..i].copy_from_slice(&c[..i]);
                    ci[i..].iter_mut().for_each(|v| *v = 0.0);
                    layers.decode(&ci, &mut a3, &mut y);
                    // dE/dy = 2·norm·(y − x)
                    for r in 0..s.d {
                        let e = y[r] - x[r];
                        err += e * e * norm;
                        let dy = 2.0 * norm * e;
                        g[o[7] + r] += dy;
                        for j in 0..s.h {
                            g[o[6] + r * s.h + j] += dy * a3[j];
                        }
                    }
                    for j in 0..s.h {
                        let da3: f64 = (0..s.d)
                            .map(|r| layers.w4[r * s.h + j] * 2.0 * norm * (y[r] - x[r]))
                            .sum();
                        dz3[j] = da3 * (1.0 - a3[j] * a3[j]);
                        g[o[5] + j] += dz3[j];
                        for m in 0..i {
                            g[o[4] + j * s.k + m] += dz3[j] * ci[m];
                        }
                    }
                    for (m, dcm) in dc.iter_mut().enumerate().take(i) {
                        *dcm += (0..s.h)
                            .map(|j| layers.w3[j * s.k + m] * dz3[j])
                            .sum::<f64>();
                    }
                }
                for m in 0..s.k {
                    g[o[3] + m] += dc[m];
                    for j in 0..s.h {
                        g[o[2] + m * s.h + j] += dc[m] * a1[j];
                    }
                }
                for j in 0..s.h {
                    let da1: f64 = (0..s.k).map(|m| layers.w2[m * s.h + j] * dc[m]).sum();
                    dz1[j] = da1 * (1.0 - a1[j] * a1[j]);
                    g[o[1] + j] += dz1[j];
                    for q in 0..s.d {
                        g[o[0] + j * s.d + q] += dz1[j] * x[q];
                    }
                }
            }
            (err, g)
        })
        .collect();
    let mut total = 0.0;
    let mut grad = vec![0.0; s.len()];
    for (e, g) in parts {
        total += e;
        grad.iter_mut().zip(&g).for_each(|(a, b)| *a += b);
    }
    debug_assert!(n > 0);
    // Weight decay: ν · mean(w²) over the weights.
    let count = (0..w.len()).filter(|&i| s.is_weight(i)).count().max(1) as f64;
    for (i, wi) in w.iter().enumerate() {
        if s.is_weight(i) {
            total += decay * wi * wi / count;
            grad[i] += 2.0 * decay * wi / count;
        }
    }
    (total, grad)
}
