//! Minimising a smooth function with argmin's L-BFGS (Moré-Thuente line search), in rounds:
//! a failed line search (it happens near convergence) then costs one round, not the run, and
//! each round restarts from the best point so far.

use std::sync::Mutex;

use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;

/// A function that returns its value and gradient together.
pub type ValueAndGradient<'a> = dyn Fn(&[f64]) -> (f64, Vec<f64>) + Sync + 'a;

/// The argmin problem, with the last evaluation cached: the line search asks for the cost and
/// the gradient at the same points.
/// The last point evaluated, its value and its gradient.
type Evaluation = (Vec<f64>, f64, Vec<f64>);

struct Problem<'a, 'f> {
    f: &'a ValueAndGradient<'f>,
    cache: Mutex<Option<Evaluation>>,
}

impl Problem<'_, '_> {
    fn eval(&self, w: &[f64]) -> (f64, Vec<f64>) {
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((p, e, g)) = cache.as_ref()
            && p.as_slice() == w
        {
            return (*e, g.clone());
        }
        let (e, g) = (self.f)(w);
        *cache = Some((w.to_vec(), e, g.clone()));
        (e, g)
    }
}

impl CostFunction for Problem<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, w: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.eval(w).0)
    }
}

impl Gradient for Problem<'_, '_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, w: &Vec<f64>) -> Result<Vec<f64>, argmin::core::Error> {
        Ok(self.eval(w).1)
    }
}

/// The minimum found from `start`: the point, its value and the iterations used.
pub fn minimise(
    f: &ValueAndGradient,
    start: Vec<f64>,
    max_iterations: u64,
    memory: usize,
) -> (Vec<f64>, f64, u64) {
    const ROUND: u64 = 500;
    let mut best_w = start;
    let mut best = f(&best_w).0;
    let mut iterations = 0;
    while iterations < max_iterations {
        let budget = ROUND.min(max_iterations - iterations);
        let solver = LBFGS::new(MoreThuenteLineSearch::new(), memory.max(1))
            .with_tolerance_grad(1e-12)
            .and_then(|s| s.with_tolerance_cost(1e-15))
            .expect("the tolerances are valid");
        let problem = Problem {
            f,
            cache: Mutex::new(None),
        };
        let Ok(result) = Executor::new(problem, solver)
            .configure(|st| st.param(best_w.clone()).max_iters(budget))
            .run()
        else {
            break;
        };
        let state = result.state();
        iterations += state.get_iter().max(1);
        let improved = state.get_best_cost() < best * (1.0 - 1e-6);
        if let Some(w) = state.get_best_param()
            && state.get_best_cost() < best
        {
            best = state.get_best_cost();
            best_w = w.clone();
        }
        if !improved || state.get_iter() < budget {
            break;
        }
    }
    (best_w, best, iterations)
}
