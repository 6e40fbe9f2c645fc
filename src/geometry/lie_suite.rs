//! One axiom suite for every Lie group (after sophus-rs `lie_group.rs`): exp/log round trips,
//! identity, inverse, associativity and the adjoint, on tangents near 0 and near π.

#![cfg(test)]

pub trait LieGroup: Sized + Copy + std::fmt::Debug {
    type Tangent: Copy + std::fmt::Debug;
    const NAME: &'static str;
    fn exp(xi: &Self::Tangent) -> Self;
    fn log(&self) -> Self::Tangent;
    fn compose(&self, o: &Self) -> Self;
    fn inverse(&self) -> Self;
    fn identity() -> Self;
    fn adjoint_apply(&self, xi: &Self::Tangent) -> Self::Tangent;
    fn distance(&self, o: &Self) -> f64;
    fn tangent_distance(a: &Self::Tangent, b: &Self::Tangent) -> f64;
    /// Test tangents, including ones near 0 and near π.
    fn tangents() -> Vec<Self::Tangent>;
}

pub fn group_axiom_suite<G: LieGroup>() {
    let tol = 1e-9;
    let name = G::NAME;
    let ts = G::tangents();
    let gs: Vec<G> = ts.iter().map(G::exp).collect();
    for (xi, g) in ts.iter().zip(&gs) {
        // log(exp(ξ)) = ξ (angles stay below π in the samples, so log is unique)
        let back = g.log();
        assert!(
            G::tangent_distance(&back, xi) < 1e-6,
            "{name}: log(exp({xi:?})) = {back:?}"
        );
        // exp(log(g)) = g
        assert!(
            G::exp(&back).distance(g) < tol,
            "{name}: exp(log(g)) != g for {xi:?}"
        );
        // identity and inverse
        assert!(
            g.compose(&G::identity()).distance(g) < tol,
            "{name}: g·e != g"
        );
        assert!(
            G::identity().compose(g).distance(g) < tol,
            "{name}: e·g != g"
        );
        assert!(
            g.compose(&g.inverse()).distance(&G::identity()) < tol,
            "{name}: g·g⁻¹ != e for {xi:?}"
        );
    }
    for a in &gs {
        for b in &gs {
            for c in gs.iter().take(4) {
                let left = a.compose(b).compose(c);
                let right = a.compose(&b.compose(c));
                assert!(left.distance(&right) < 1e-8, "{name}: associativity");
            }
            // adjoint: g·exp(ξ)·g⁻¹ = exp(Ad_g ξ)
            let xi = b.log();
            let lhs = a.compose(&G::exp(&xi)).compose(&a.inverse());
            let rhs = G::exp(&a.adjoint_apply(&xi));
            assert!(lhs.distance(&rhs) < 1e-7, "{name}: adjoint for {xi:?}");
        }
    }
}
