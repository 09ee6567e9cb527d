//! The problem the iterations solve: energy (16) at given momenta, and its exact Jacobian.

use super::search_space::SearchSpace;
use crate::flow::tangent::{position_jacobian_in_pool, TangentAlong};
use crate::flow::{ControlPoints, PrimalFlow};
pub use crate::numeric::cancellation::cancellation_of;
use cbd_protocol::Normalisation;
use faer::Mat;
use std::cell::{Cell, OnceCell};
use std::time::Instant;

/// Where the fit's time goes, and how many exact Jacobians it formed.
#[derive(Default)]
pub(super) struct Timers {
    pub flow: Cell<f64>,
    pub tangent: Cell<f64>,
    pub solve: Cell<f64>,
    pub tangents: Cell<usize>,
}

impl Timers {
    /// Runs `f`, adding its wall time to `slot`.
    pub fn time<T>(slot: &Cell<f64>, f: impl FnOnce() -> T) -> T {
        let t0 = Instant::now();
        let out = f();
        slot.set(slot.get() + t0.elapsed().as_secs_f64());
        out
    }
}

/// Energy (16) and what it was computed from.
pub(super) struct Evaluated {
    pub energy: f64,
    pub regulariser: f64,
    /// (k1 − y)/σ, N·m.
    pub residual: Vec<f64>,
    pub flow: PrimalFlow,
}

pub(super) struct Problem<'a> {
    pub cp: &'a ControlPoints,
    /// y, normalised, N·m.
    pub target: Vec<f64>,
    pub sigma: f64,
    pub space: SearchSpace,
    pub timers: Timers,
    /// Along the eigenspace, the first stage's P0-independent part, formed when the first exact
    /// Jacobian is needed and kept.
    along: OnceCell<TangentAlong>,
}

impl<'a> Problem<'a> {
    pub fn new(cp: &'a ControlPoints, target: Vec<f64>, sigma: f64, space: SearchSpace) -> Self {
        Problem { cp, target, sigma, space, timers: Timers::default(), along: OnceCell::new() }
    }

    /// Energy (16) at search coordinates `p`; None when the flow or the energy is not finite.
    pub fn evaluate(&self, p: &[f64]) -> Option<Evaluated> {
        let flow = Timers::time(&self.timers.flow, || self.cp.integrate(&self.space.momenta_of(p)).ok())?;
        let k1 = flow.positions(self.cp.dims);
        let residual: Vec<f64> = k1.iter().zip(&self.target).map(|(k, y)| (k - y) / self.sigma).collect();
        let regulariser = 0.5 * quad_form(&self.space.k_reg, p);
        let energy = regulariser + 0.5 * residual.iter().map(|r| r * r).sum::<f64>();
        energy.is_finite().then_some(Evaluated { energy, regulariser, residual, flow })
    }

    /// d k1 / d p at `flow`'s momenta, from the tangent flow.
    pub fn exact_jacobian(&self, flow: &PrimalFlow) -> Mat<f64> {
        self.timers.tangents.set(self.timers.tangents.get() + 1);
        Timers::time(&self.timers.tangent, || match &self.space.basis {
            None => position_jacobian_in_pool(self.cp, flow),
            Some(e) => self.along.get_or_init(|| TangentAlong::new(self.cp, e.basis.clone())).jacobian(self.cp, flow),
        })
    }

    /// RMS position error of normalised residual `r` ((k1 − y)/σ), in user units.
    pub fn rms(&self, r: &[f64], norm: &Normalisation) -> f64 {
        let m = self.cp.dims.m;
        norm.length_to_user((r.iter().map(|v| v * v).sum::<f64>() / (r.len() / m) as f64).sqrt() * self.sigma)
    }
}

/// pᵀ K p.
pub(super) fn quad_form(k: &Mat<f64>, p: &[f64]) -> f64 {
    // (K p)_i summed over j in order, column by column (contiguous).
    let mut kp = vec![0.0; p.len()];
    for (j, pj) in p.iter().enumerate() {
        for (r, kij) in kp.iter_mut().zip(k.col(j).iter()) {
            *r += kij * pj;
        }
    }
    p.iter().zip(&kp).map(|(pi, r)| pi * r).sum()
}

/// The Gauss–Newton model of the energy after step `step` (to `trial`) with Jacobian `jac`:
/// ½ |r + J δ/σ|² + ½ trialᵀ K trial.
pub(super) fn model_energy(jac: &Mat<f64>, k: &Mat<f64>, sigma: f64, residual: &[f64], step: &[f64], trial: &[f64]) -> f64 {
    let mut r: Vec<f64> = residual.to_vec();
    for (j, d) in step.iter().enumerate() {
        let scale = d / sigma;
        for (ri, jij) in r.iter_mut().zip(jac.col(j).iter()) {
            *ri += jij * scale;
        }
    }
    0.5 * r.iter().map(|v| v * v).sum::<f64>() + 0.5 * quad_form(k, trial)
}
