//! Linear PCA of the jaw vectors (the paper's Eq. 4).

use nalgebra::{DMatrix, Vector6};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Pca {
    pub mean: [f64; 6],
    /// Principal directions, largest variance first (unit vectors).
    pub components: Vec<[f64; 6]>,
    /// Singular values of the centred data matrix divided by √n: the RMS extent (mm) of the
    /// data along each direction.
    pub singular_values: Vec<f64>,
}

impl Pca {
    pub fn fit(data: &[Vector6<f64>]) -> Pca {
        let n = data.len().max(1);
        let mean = data.iter().sum::<Vector6<f64>>() / n as f64;
        let mut m = DMatrix::<f64>::zeros(data.len(), 6);
        for (i, v) in data.iter().enumerate() {
            for k in 0..6 {
                m[(i, k)] = v[k] - mean[k];
            }
        }
        // The right singular vectors of the n×6 matrix, via the 6×6 scatter matrix.
        let scatter = m.transpose() * &m;
        let eig = nalgebra::SymmetricEigen::new(scatter);
        let mut order: Vec<usize> = (0..6).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let components = order
            .iter()
            .map(|&j| {
                let col = eig.eigenvectors.column(j);
                // Sign: the largest coordinate positive, so the basis is reproducible.
                let big = (0..6)
                    .max_by(|&a, &b| col[a].abs().total_cmp(&col[b].abs()))
                    .unwrap_or(0);
                let s = if col[big] < 0.0 { -1.0 } else { 1.0 };
                std::array::from_fn(|k| s * col[k])
            })
            .collect();
        let singular_values = order
            .iter()
            .map(|&j| (eig.eigenvalues[j].max(0.0) / n as f64).sqrt())
            .collect();
        Pca {
            mean: mean.into(),
            components,
            singular_values,
        }
    }

    /// The vector rebuilt from its first `k` principal components.
    pub fn reconstruct(&self, v: &Vector6<f64>, k: usize) -> Vector6<f64> {
        let mean = Vector6::from(self.mean);
        let centred = v - mean;
        let mut out = mean;
        for c in self.components.iter().take(k) {
            let c = Vector6::from(*c);
            out += c * c.dot(&centred);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_on_a_line_has_one_component() {
        let dir = Vector6::new(1.0, 2.0, 0.0, -1.0, 0.5, 3.0).normalize();
        let data: Vec<Vector6<f64>> = (0..20)
            .map(|i| Vector6::repeat(1.0) + dir * (i as f64 - 7.0))
            .collect();
        let pca = Pca::fit(&data);
        assert!(pca.singular_values[0] > 1.0 && pca.singular_values[1] < 1e-6);
        assert!((Vector6::from(pca.components[0]).dot(&dir).abs() - 1.0).abs() < 1e-9);
        let v = Vector6::repeat(1.0) + dir * 2.5;
        assert!((pca.reconstruct(&v, 1) - v).norm() < 1e-9);
    }
}
