//! The joint kernel's axis forms as the trainer uses them: one descriptor per form (docs/DESIGN.md
//! §4 "Worked changes (issue 41)", §9) — its parameter's name and JSON key, the joints it is the
//! default for and its default, its exponent per pair of rows for the evidence's table, where the
//! searches start and the box they stay in, and its own series for the expansion (§11). The evidence
//! (`evidence/`), the kernel-ridge peer, `calibrate`, `plan`, `evaluation` and `expansion` call these
//! and never match on the forms; the runtime's side of a form is `runtime/src/kernel/axis.rs`.
//!
//! Joint values are not normalised (only task-space lengths are, `cbd_protocol::Normalisation`), so a
//! form's parameter is the same number in the user's units, the search's and the blob's.

pub mod series;
pub mod weights;

use cbd_protocol::{JointKernel, JointKernelAxis, NominalModel};
use series::AxisSeries;

/// One form of the joint kernel's per-axis factor e^{f}, with f = w(p) t(Δ): a weight of the
/// form's parameter p times a term of the pair's joint difference Δ (the evidence tabulates t once
/// and costs one `exp` per pair at any p).
pub trait AxisForm: Sync {
    /// Its name in words ("periodic").
    fn name(&self) -> &'static str;
    /// Its parameter in one-line reports ("b" in `b=1.3`).
    fn label(&self) -> &'static str;
    /// Its parameter's key in the JSON reports ("periodic_b").
    fn json_key(&self) -> &'static str;
    /// Whether the kernel repeats after a whole turn of the joint.
    fn periodic(&self) -> bool;
    /// Whether it is the default form of a revolute (`true`) or prismatic (`false`) joint.
    fn default_for(&self, revolute: bool) -> bool;
    /// The parameter of the default kernel (the paper's prior and the placeholders).
    fn default_parameter(&self) -> f64 {
        1.0
    }
    /// The blob's axis of parameter `p`; `None` for a form the protocol has no variant for (a test's).
    fn axis(&self, p: f64) -> Option<JointKernelAxis>;
    /// The parameter of `axis` when it is of this form.
    fn parameter(&self, axis: &JointKernelAxis) -> Option<f64>;
    /// t(Δ) of a pair of joint values Δ apart.
    fn pair_term(&self, delta: f64) -> f64;
    /// d ln w / d ln p: w = e^{slope ln p}.
    fn log_weight_slope(&self) -> f64;
    /// w at ln p.
    fn weight(&self, log_p: f64) -> f64 {
        (self.log_weight_slope() * log_p).exp()
    }
    /// ∂(w t)/∂ ln p.
    fn exponent_log_derivative(&self, w: f64, t: f64) -> f64 {
        self.log_weight_slope() * w * t
    }
    /// ln p at which pairs whose terms add up to −`spread` over the axes have kernel ½: w = ln 2 / spread.
    fn half_kernel_log_parameter(&self, spread: f64) -> f64 {
        (2f64.ln() / spread).ln() / self.log_weight_slope()
    }
    /// The evidence's box for ln p, given the half-kernel start `log_half`.
    fn evidence_bounds(&self, log_half: f64) -> (f64, f64);
    /// Its own series on |x| ≤ `range` (the shares of its basis functions, §11), `None` without one.
    fn series(&self, p: f64, range: f64) -> Option<AxisSeries>;
}

/// b (cos Δ − 1), revolute joints.
pub struct Periodic;

impl AxisForm for Periodic {
    fn name(&self) -> &'static str {
        "periodic"
    }
    fn label(&self) -> &'static str {
        "b"
    }
    fn json_key(&self) -> &'static str {
        "periodic_b"
    }
    fn periodic(&self) -> bool {
        true
    }
    fn default_for(&self, revolute: bool) -> bool {
        revolute
    }
    fn axis(&self, b: f64) -> Option<JointKernelAxis> {
        Some(JointKernelAxis::Periodic { b })
    }
    fn parameter(&self, axis: &JointKernelAxis) -> Option<f64> {
        if let JointKernelAxis::Periodic { b } = *axis {
            Some(b)
        } else {
            None
        }
    }
    fn pair_term(&self, delta: f64) -> f64 {
        delta.cos() - 1.0
    }
    fn log_weight_slope(&self) -> f64 {
        1.0
    }
    /// b from 1e-5 to 1e3.
    fn evidence_bounds(&self, _log_half: f64) -> (f64, f64) {
        (1e-5f64.ln(), 1e3f64.ln())
    }
    fn series(&self, b: f64, _range: f64) -> Option<AxisSeries> {
        Some(AxisSeries::periodic(b))
    }
}

/// −Δ²/(2ℓ²), prismatic joints: w = 1/ℓ², t = −Δ²/2.
pub struct Gaussian;

impl AxisForm for Gaussian {
    fn name(&self) -> &'static str {
        "Gaussian"
    }
    fn label(&self) -> &'static str {
        "l"
    }
    fn json_key(&self) -> &'static str {
        "gaussian_width"
    }
    fn periodic(&self) -> bool {
        false
    }
    fn default_for(&self, revolute: bool) -> bool {
        !revolute
    }
    fn axis(&self, width: f64) -> Option<JointKernelAxis> {
        Some(JointKernelAxis::Gaussian { width })
    }
    fn parameter(&self, axis: &JointKernelAxis) -> Option<f64> {
        if let JointKernelAxis::Gaussian { width } = *axis {
            Some(width)
        } else {
            None
        }
    }
    fn pair_term(&self, delta: f64) -> f64 {
        -0.5 * delta * delta
    }
    fn log_weight_slope(&self) -> f64 {
        -2.0
    }
    /// Σ s_d / ℓ² = ln 2.
    fn half_kernel_log_parameter(&self, spread: f64) -> f64 {
        (spread / 2f64.ln()).sqrt().ln()
    }
    /// ℓ within 1e±3 of the half-kernel width.
    fn evidence_bounds(&self, log_half: f64) -> (f64, f64) {
        (log_half - 1e3f64.ln(), log_half + 1e3f64.ln())
    }
    fn series(&self, width: f64, range: f64) -> Option<AxisSeries> {
        Some(AxisSeries::gaussian(range / width))
    }
}

/// Every form the blob can carry, one per `JointKernelAxis` variant.
pub static FORMS: [&(dyn AxisForm + 'static); 2] = [&Periodic, &Gaussian];

/// The form of `axis`.
pub fn form_of(axis: &JointKernelAxis) -> &'static dyn AxisForm {
    FORMS.iter().copied().find(|f| f.parameter(axis).is_some()).expect("every JointKernelAxis variant has a form in FORMS")
}

/// `axis` as (its form, its parameter).
pub fn form_and_parameter(axis: &JointKernelAxis) -> (&'static dyn AxisForm, f64) {
    let form = form_of(axis);
    (form, form.parameter(axis).unwrap_or(f64::NAN))
}

/// The default form of a revolute (`true`) or prismatic joint.
pub fn default_form(revolute: bool) -> &'static dyn AxisForm {
    FORMS.iter().copied().find(|f| f.default_for(revolute)).expect("a default form for either joint type")
}

/// The default form of every joint of `nominal`: what the evidence and the peers search.
pub fn forms_of(nominal: &NominalModel) -> Vec<&'static dyn AxisForm> {
    (0..nominal.n_joints()).map(|d| default_form(nominal.is_revolute(d))).collect()
}

/// One axis per joint of `nominal`: its default form at its default parameter.
pub fn default_axes(nominal: &NominalModel) -> Vec<JointKernelAxis> {
    forms_of(nominal).iter().map(|f| f.axis(f.default_parameter()).expect("the default forms are the blob's")).collect()
}

/// The axes `forms` at log parameters `log_p`.
pub fn axes_at(forms: &[&dyn AxisForm], log_p: &[f64]) -> Vec<JointKernelAxis> {
    forms.iter().zip(log_p).map(|(f, l)| f.axis(l.exp()).expect("a form the blob can carry")).collect()
}

/// The joint kernel's axes as series: periodic axes exactly, Gaussian axes on |x_d| ≤ `ranges[d]`;
/// `None` when a form has no series of its own.
pub fn joint_series(kernel: &JointKernel, ranges: &[f64]) -> Option<Vec<AxisSeries>> {
    kernel
        .axes
        .iter()
        .zip(ranges)
        .map(|(axis, &range)| {
            let (form, p) = form_and_parameter(axis);
            form.series(p, range)
        })
        .collect()
}

/// `{key: parameter}` of `axis` for the JSON reports.
pub fn axis_json(axis: &JointKernelAxis) -> serde_json::Value {
    let (form, p) = form_and_parameter(axis);
    let mut map = serde_json::Map::new();
    map.insert(form.json_key().to_string(), p.into());
    serde_json::Value::Object(map)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A test-only form, the worked change of docs/DESIGN.md §4: b (cos 2Δ − 1), a kernel that repeats
    /// after a half turn (the runtime's twin is in `runtime/src/kernel/axis.rs`'s tests). The
    /// protocol has no variant for it, so it stops short of a blob.
    pub(crate) struct HalfTurn;

    impl AxisForm for HalfTurn {
        fn name(&self) -> &'static str {
            "half-turn"
        }
        fn label(&self) -> &'static str {
            "b2"
        }
        fn json_key(&self) -> &'static str {
            "half_turn_b"
        }
        fn periodic(&self) -> bool {
            true
        }
        fn default_for(&self, _revolute: bool) -> bool {
            false
        }
        fn axis(&self, _b: f64) -> Option<JointKernelAxis> {
            None
        }
        fn parameter(&self, _axis: &JointKernelAxis) -> Option<f64> {
            None
        }
        fn pair_term(&self, delta: f64) -> f64 {
            (2.0 * delta).cos() - 1.0
        }
        fn log_weight_slope(&self) -> f64 {
            1.0
        }
        fn evidence_bounds(&self, _log_half: f64) -> (f64, f64) {
            (1e-5f64.ln(), 1e3f64.ln())
        }
        /// exp(b (cos u − 1)) at u = 2Δ: the periodic form's shares, harmonics 2h.
        fn series(&self, b: f64, _range: f64) -> Option<AxisSeries> {
            Some(AxisSeries::periodic(b))
        }
    }

    #[test]
    fn every_variant_has_one_form_and_the_defaults_are_the_former_ones() {
        for axis in [JointKernelAxis::Periodic { b: 1.3 }, JointKernelAxis::Gaussian { width: 0.7 }] {
            let forms: Vec<_> = FORMS.iter().filter(|f| f.parameter(&axis).is_some()).collect();
            assert_eq!(forms.len(), 1, "{axis:?}");
            let (form, p) = form_and_parameter(&axis);
            assert_eq!(form.axis(p), Some(axis));
        }
        assert_eq!(default_form(true).axis(1.0), Some(JointKernelAxis::Periodic { b: 1.0 }));
        assert_eq!(default_form(false).axis(1.0), Some(JointKernelAxis::Gaussian { width: 1.0 }));
        assert_eq!(axis_json(&JointKernelAxis::Periodic { b: 2.0 }), serde_json::json!({ "periodic_b": 2.0 }));
        assert_eq!(axis_json(&JointKernelAxis::Gaussian { width: 2.0 }), serde_json::json!({ "gaussian_width": 2.0 }));
    }

    /// The descriptors' generic formulas give the bits the per-form code gave before.
    #[test]
    fn the_generic_formulas_keep_the_former_bits() {
        for x in [-3.7, -0.4, 0.0, 0.25, 1.9, 12.0] {
            assert_eq!(Periodic.weight(x).to_bits(), x.exp().to_bits());
            assert_eq!(Gaussian.weight(x).to_bits(), (-2.0 * x).exp().to_bits());
            for (w, t) in [(0.3, -0.7), (17.0, -1e-3)] {
                assert_eq!(Periodic.exponent_log_derivative(w, t).to_bits(), (w * t).to_bits());
                assert_eq!(Gaussian.exponent_log_derivative(w, t).to_bits(), (-2.0 * w * t).to_bits());
            }
            let total = x.abs() + 0.01;
            assert_eq!(Periodic.half_kernel_log_parameter(total).to_bits(), (2f64.ln() / total).ln().to_bits());
            for shift in [0.0, -4f64.ln() * 2.0, 4f64.ln(), 1.3] {
                assert_eq!((x + shift / Periodic.log_weight_slope()).to_bits(), (x + shift).to_bits());
                assert_eq!((x + shift / Gaussian.log_weight_slope()).to_bits(), (x - 0.5 * shift).to_bits());
                for dir in [1.0, -1.0] {
                    assert_eq!((dir * shift / Gaussian.log_weight_slope()).to_bits(), (-0.5 * dir * shift).to_bits());
                }
            }
        }
    }
}
