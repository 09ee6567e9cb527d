//! One joint's factor e^{f_d(x_d, x'_d)} of K_V (docs/DESIGN.md §1, §11): every axis form's
//! mathematics in one place — its features, f with its first two derivatives, and the factors of its
//! own basis for the expansion. `kernel`, `flow` and `expansion` call [`AxisKernel`] and never match
//! on the forms; a new form is a type here, its `impl AxisKernel` and one arm of `with_form!`
//! (docs/DESIGN.md §4 "Worked changes (issue 41)").

use super::hermite::hermite_factors;
use super::FEATURES_PER_JOINT;
use crate::real::Real;
use cbd_protocol::JointKernelAxis;

/// One axis form of the joint kernel.
pub trait AxisKernel {
    /// The quantities f needs from one joint value, computed once per configuration (in f64,
    /// rounded once to [`Real`]), so that a kernel value costs one `exp` and no other transcendental.
    fn features(&self, xd: f64) -> [Real; FEATURES_PER_JOINT];
    /// f, ∂f/∂x and ∂²f/∂x² at (x, x') from x's features `a` and x''s features `b`.
    fn terms(&self, a: &[Real; FEATURES_PER_JOINT], b: &[Real; FEATURES_PER_JOINT]) -> (Real, Real, Real);
    /// The factors F, F', F'' (derivatives in x) of the form's own basis at x_d, every code of
    /// order ≤ `order` (≤ `MAX_EXPANSION_ORDER`), in f64: `set(code, F, F', F'')`. A form without
    /// an expansion of its own sets none (the blob's validation admits no codes on its axes).
    fn basis_factors(&self, xd: f64, order: usize, set: impl FnMut(usize, f64, f64, f64));
}

/// f = b (cos Δ − 1), periodic in 2π (revolute joints): features (cos x, sin x); own basis
/// cos hx (code `h << 1`) and sin hx (`h << 1 | 1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Periodic {
    /// b > 0: larger is narrower.
    pub b: f64,
}

impl AxisKernel for Periodic {
    #[inline(always)]
    fn features(&self, xd: f64) -> [Real; FEATURES_PER_JOINT] {
        // In f64, rounded once to the evaluation scalar.
        let (s, c) = libm::sincos(xd);
        [c as Real, s as Real]
    }

    /// cos Δ = cos x cos x' + sin x sin x', sin Δ = sin x cos x' − cos x sin x'.
    #[inline(always)]
    fn terms(&self, a: &[Real; FEATURES_PER_JOINT], b: &[Real; FEATURES_PER_JOINT]) -> (Real, Real, Real) {
        let beta = self.b as Real;
        let cos_delta = a[0] * b[0] + a[1] * b[1];
        let sin_delta = a[1] * b[0] - a[0] * b[1];
        (beta * (cos_delta - 1.0), -beta * sin_delta, -beta * cos_delta)
    }

    /// cos hx: (cos, −h sin, −h² cos); sin hx: (sin, h cos, −h² sin), harmonics by
    /// cos((h+1)x) = cos hx cos x − sin hx sin x, sin((h+1)x) = sin hx cos x + cos hx sin x.
    #[inline(always)]
    fn basis_factors(&self, xd: f64, order: usize, mut set: impl FnMut(usize, f64, f64, f64)) {
        let (s1, c1) = libm::sincos(xd);
        let (mut c, mut s) = (1.0, 0.0);
        for k in 0..=order {
            let h = k as f64;
            set(2 * k, c, -h * s, -(h * h) * c);
            set(2 * k + 1, s, h * c, -(h * h) * s);
            (c, s) = (c * c1 - s * s1, s * c1 + c * s1);
        }
    }
}

/// f = −Δ²/(2ℓ²) (prismatic joints): features (x, 0); own basis the Hermite functions
/// e^{−u²/2} u^k/√(k!) of u = x/ℓ (code `k << 1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gaussian {
    /// ℓ > 0, in the joint's unit.
    pub width: f64,
}

impl AxisKernel for Gaussian {
    #[inline(always)]
    fn features(&self, xd: f64) -> [Real; FEATURES_PER_JOINT] {
        [xd as Real, 0.0]
    }

    #[inline(always)]
    fn terms(&self, a: &[Real; FEATURES_PER_JOINT], b: &[Real; FEATURES_PER_JOINT]) -> (Real, Real, Real) {
        let width = self.width as Real;
        let s = 1.0 / (width * width);
        let delta = a[0] - b[0];
        (-0.5 * delta * delta * s, -delta * s, -s)
    }

    /// The Hermite function of u = x/ℓ; its derivatives in x are those in u over ℓ, ℓ². (Gaussian
    /// codes have no sine bit; both entries hold the factor, as the order does.)
    #[inline(always)]
    fn basis_factors(&self, xd: f64, order: usize, mut set: impl FnMut(usize, f64, f64, f64)) {
        let u = xd / self.width;
        let inv_width = 1.0 / self.width;
        hermite_factors(u, order, |k, f0, f1, f2| {
            let (f1, f2) = (f1 * inv_width, f2 * (inv_width * inv_width));
            set(2 * k, f0, f1, f2);
            set(2 * k + 1, f0, f1, f2);
        });
    }
}

/// `$body` with `$form` bound to `$axis`'s form: the one place the runtime names the variants.
macro_rules! with_form {
    ($axis:expr, |$form:ident| $body:expr) => {
        match *$axis {
            JointKernelAxis::Periodic { b } => {
                let $form = Periodic { b };
                $body
            }
            JointKernelAxis::Gaussian { width } => {
                let $form = Gaussian { width };
                $body
            }
        }
    };
}

impl AxisKernel for JointKernelAxis {
    #[inline(always)]
    fn features(&self, xd: f64) -> [Real; FEATURES_PER_JOINT] {
        with_form!(self, |form| form.features(xd))
    }

    #[inline(always)]
    fn terms(&self, a: &[Real; FEATURES_PER_JOINT], b: &[Real; FEATURES_PER_JOINT]) -> (Real, Real, Real) {
        with_form!(self, |form| form.terms(a, b))
    }

    #[inline(always)]
    fn basis_factors(&self, xd: f64, order: usize, set: impl FnMut(usize, f64, f64, f64)) {
        with_form!(self, |form| form.basis_factors(xd, order, set))
    }
}

/// A test-only form, the worked change of docs/DESIGN.md §4 "Worked changes (issue 41)": what a new
/// form implements, checked against finite differences and its own basis against its kernel, through
/// the generic kernel and basis code.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::{axes_features, axes_kernel_parts_n};
    use cbd_protocol::MAX_JOINTS;

    /// f = b (cos 2Δ − 1): periodic in a half turn (a joint symmetric under π). Features
    /// (cos 2x, sin 2x); own basis cos 2hx (`h << 1`), sin 2hx (`h << 1 | 1`), whose shares are the
    /// periodic form's e^{−b} I_h(b) (2 − δ_h0) (exp(b (cos u − 1)) at u = 2Δ).
    #[derive(Clone, Copy)]
    struct HalfTurn {
        b: f64,
    }

    impl AxisKernel for HalfTurn {
        fn features(&self, xd: f64) -> [Real; FEATURES_PER_JOINT] {
            let (s, c) = libm::sincos(2.0 * xd);
            [c as Real, s as Real]
        }

        fn terms(&self, a: &[Real; FEATURES_PER_JOINT], b: &[Real; FEATURES_PER_JOINT]) -> (Real, Real, Real) {
            let beta = self.b as Real;
            let cos_2delta = a[0] * b[0] + a[1] * b[1];
            let sin_2delta = a[1] * b[0] - a[0] * b[1];
            (beta * (cos_2delta - 1.0), -2.0 * beta * sin_2delta, -4.0 * beta * cos_2delta)
        }

        fn basis_factors(&self, xd: f64, order: usize, mut set: impl FnMut(usize, f64, f64, f64)) {
            for k in 0..=order {
                let w = 2.0 * k as f64;
                let (s, c) = libm::sincos(w * xd);
                set(2 * k, c, -w * s, -(w * w) * c);
                set(2 * k + 1, s, w * c, -(w * w) * s);
            }
        }
    }

    const AXES: [HalfTurn; 3] = [HalfTurn { b: 0.7 }, HalfTurn { b: 1.3 }, HalfTurn { b: 0.2 }];
    const GAMMA: f64 = 2.5;

    /// Central-difference step and tolerance for the evaluation scalar.
    fn step_and_tolerance() -> (f64, f64) {
        let eps = Real::EPSILON as f64;
        (libm::cbrt(eps), 100.0 * libm::pow(eps, 2.0 / 3.0))
    }

    /// K_V through the generic code, with per-axis f', f''.
    fn kernel(x: &[f64; 3], xp: &[f64; 3]) -> (f64, [Real; MAX_JOINTS], [Real; MAX_JOINTS]) {
        let (mut fx, mut fxp) = ([[0.0; FEATURES_PER_JOINT]; MAX_JOINTS], [[0.0; FEATURES_PER_JOINT]; MAX_JOINTS]);
        axes_features(&AXES, x, &mut fx);
        axes_features(&AXES, xp, &mut fxp);
        let (mut first, mut second) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        let k = axes_kernel_parts_n(GAMMA, &AXES, 3, &fx, &fxp, &mut first, &mut second);
        (k as f64, first, second)
    }

    #[test]
    fn a_new_form_evaluates_through_the_generic_kernel_and_its_derivatives_match_finite_differences() {
        let (x, xp) = ([0.3, -1.2, 2.9], [1.1, 0.4, -2.5]);
        let (k, first, second) = kernel(&x, &xp);
        // The formula itself, independently.
        let direct =
            GAMMA * libm::exp(AXES.iter().zip(x.iter().zip(&xp)).map(|(a, (u, v))| a.b * (libm::cos(2.0 * (u - v)) - 1.0)).sum::<f64>());
        assert!((k - direct).abs() <= 16.0 * Real::EPSILON as f64 * direct, "{k} vs {direct}");
        // ∂K/∂x_d = K f'_d and ∂²K/∂x_d² = K (f'_d² + f''_d) against central differences of K.
        let (h, tol) = step_and_tolerance();
        for d in 0..3 {
            let (mut up, mut down) = (x, x);
            up[d] += h;
            down[d] -= h;
            let (ku, kd) = (kernel(&up, &xp).0, kernel(&down, &xp).0);
            let gradient = k * first[d] as f64;
            let fd = (ku - kd) / (2.0 * h);
            assert!((fd - gradient).abs() < tol * (1.0 + gradient.abs()), "axis {d}: {fd} vs {gradient}");
            let curvature = k * ((first[d] * first[d]) as f64 + second[d] as f64);
            let (h2, tol2) = (libm::sqrt(h), 10.0 * libm::sqrt(tol));
            let (mut up, mut down) = (x, x);
            up[d] += h2;
            down[d] -= h2;
            let fd2 = (kernel(&up, &xp).0 - 2.0 * k + kernel(&down, &xp).0) / (h2 * h2);
            assert!((fd2 - curvature).abs() < tol2 * (1.0 + curvature.abs()), "axis {d}: {fd2} vs {curvature}");
        }
        // Periodic in a half turn.
        let shifted = kernel(&[x[0] + core::f64::consts::PI, x[1], x[2]], &xp).0;
        assert!((shifted - k).abs() <= 16.0 * Real::EPSILON as f64 * k);
    }

    /// e^{−b} I_h(b), by the series Σ_k (b/2)^{2k+h} / (k! (k+h)!).
    fn scaled_bessel(h: usize, b: f64) -> f64 {
        let mut term = libm::pow(0.5 * b, h as f64) / (1..=h).map(|i| i as f64).product::<f64>();
        let mut sum = 0.0;
        for k in 0..60 {
            sum += term;
            term *= 0.25 * b * b / (((k + 1) * (k + 1 + h)) as f64);
        }
        libm::exp(-b) * sum
    }

    #[test]
    fn a_new_form_s_own_basis_reproduces_its_kernel_through_the_generic_basis_code() {
        const ORDER: usize = 15;
        let n = 3;
        // Every mode up to ORDER per axis would be 25³ rows: one axis varies at a time, the others
        // at order 0 (their factor 1), so each row is one axis's term.
        let mut codes = [0u8; 3 * 3 * (2 * ORDER + 1)];
        for (row, code_row) in codes.chunks_exact_mut(n).enumerate() {
            let (d, c) = (row / (2 * ORDER + 1), row % (2 * ORDER + 1));
            code_row[d] = (c + 1) as u8; // codes 1..=2 ORDER + 1 (code 1, the sine of order 0, is skipped below)
        }
        let orders = core::array::from_fn(|d| if d < n { ORDER as u8 } else { 0 });
        let (x, xp) = ([0.3, -1.2, 2.9], [1.1, 0.4, -2.5]);
        let row_len = crate::expansion::joint_row_len(n);
        let rows_of = |x: &[f64; 3]| {
            let mut rows = [0.0 as Real; 3 * 3 * (2 * ORDER + 1) * 13];
            crate::expansion::basis_functions::write_axes_basis(&AXES, &codes, &orders, n, x, &mut rows, true);
            rows
        };
        let (rx, rxp) = (rows_of(&x), rows_of(&xp));
        // Per axis: Σ_h ω_h (F_cos(x) F_cos(x') + F_sin(x) F_sin(x')) = exp(b (cos 2Δ − 1)).
        for (d, axis) in AXES.iter().enumerate() {
            let mut sum = scaled_bessel(0, axis.b); // code 0 is the constant 1 at both points
            for c in 1..2 * ORDER + 1 {
                let code = c + 1;
                let h = code >> 1;
                if h == 0 {
                    continue;
                }
                let row = d * (2 * ORDER + 1) + c;
                let (phi, phip) = (rx[row * row_len] as f64, rxp[row * row_len] as f64);
                sum += 2.0 * scaled_bessel(h, axis.b) * phi * phip;
            }
            let exact = libm::exp(axis.b * (libm::cos(2.0 * (x[d] - xp[d])) - 1.0));
            assert!((sum - exact).abs() < 1e3 * Real::EPSILON as f64, "axis {d}: {sum} vs {exact}");
        }
        // The rows' gradients and Hessians (the generic product rule over the form's factors)
        // against central differences of φ.
        let (h, tol) = step_and_tolerance();
        for d in 0..n {
            let (mut up, mut down) = (x, x);
            up[d] += h;
            down[d] -= h;
            let (ru, rd) = (rows_of(&up), rows_of(&down));
            for row in 0..codes.len() / n {
                let at = row * row_len;
                let fd = (ru[at] - rd[at]) as f64 / (2.0 * h);
                let grad = rx[at + 1 + d] as f64;
                assert!((fd - grad).abs() < 1e3 * tol * (1.0 + grad.abs()), "row {row} axis {d}: {fd} vs {grad}");
                let fd2 = (ru[at + 1 + d] - rd[at + 1 + d]) as f64 / (2.0 * h);
                let hess = rx[at + 1 + n + d * n + d] as f64;
                assert!((fd2 - hess).abs() < 1e3 * tol * (1.0 + hess.abs()), "row {row} axis {d}: {fd2} vs {hess}");
            }
        }
    }

    /// K_V of half-turn axes: the flow's kernel type, as the blob's `JointKernel` is.
    struct HalfTurnKernel {
        gamma: f64,
        axes: [HalfTurn; 2],
    }

    impl crate::kernel::JointAxes for HalfTurnKernel {
        type Axis = HalfTurn;
        fn gamma(&self) -> f64 {
            self.gamma
        }
        fn axes(&self) -> &[HalfTurn] {
            &self.axes
        }
    }

    /// The generic flow (eq. 17, 19) with the new form: its control-point rates against the
    /// formulas written out, dk = w(k) − J v(x), dP = −Dw(k)ᵀ P − (div v)(x) P, and its integration.
    #[test]
    fn a_new_form_drives_the_generic_flow() {
        use crate::flow::{
            control_point_rates, control_point_rates_with_features, control_points::integrate_control_points, write_samples, Dims,
            FlowParams,
        };
        use crate::kernel::write_features;
        use cbd_protocol::{Integrator, IntegratorMethod, MomentumLaw, TaskKernel};
        const COUNT: usize = 5;
        let dims = Dims { n: 2, m: 2 };
        let kernel = HalfTurnKernel { gamma: 1.7, axes: [HalfTurn { b: 0.7 }, HalfTurn { b: 1.3 }] };
        let task = TaskKernel { width: 0.9 };
        let params = FlowParams { dims, joint_kernel: &kernel, task_kernel: &task, law: MomentumLaw::WithDivergence };
        let points: [f64; 2 * COUNT] = [0.1, -2.0, 1.5, 0.3, -0.7, 2.9, 3.0, -1.1, 0.4, -2.5];
        // State per point: k (2), J (2 × 2, row-major), P (2).
        let mut state = [0.0 as Real; 8 * COUNT];
        let mut r = 0x9e37_79b9u32;
        for v in state.iter_mut() {
            r = r.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *v = ((r >> 8) as f64 / 16_777_216.0 - 0.5) as Real;
        }
        let mut samples = [0.0 as Real; 6 * COUNT];
        write_samples(dims, &state, &mut samples);
        let mut rates = [0.0 as Real; 8 * COUNT];
        control_point_rates(&params, &points, &state, &samples, 0..COUNT, &mut rates);
        let mut features = [0.0 as Real; 4 * COUNT];
        write_features(&kernel, 2, &points, &mut features);
        let mut from_features = [0.0 as Real; 8 * COUNT];
        control_point_rates_with_features(&params, &features, &state, &samples, 0..COUNT, &mut from_features);
        assert_eq!(rates, from_features);
        let tol = 1e3 * Real::EPSILON as f64;
        let s = |i: usize, k: usize| state[8 * i + k] as f64;
        for i in 0..COUNT {
            let (mut v, mut div, mut w, mut dw) = ([0.0; 2], 0.0, [0.0; 2], [[0.0; 2]; 2]);
            for j in 0..COUNT {
                let u = [0, 1].map(|d| s(j, 2 + d) * s(j, 6) + s(j, 4 + d) * s(j, 7)); // Jᵀ P
                let delta = [0, 1].map(|d| points[2 * i + d] - points[2 * j + d]);
                let k = kernel.gamma * libm::exp((0..2).map(|d| kernel.axes[d].b * (libm::cos(2.0 * delta[d]) - 1.0)).sum::<f64>());
                for d in 0..2 {
                    v[d] += k * u[d];
                    div += u[d] * k * (-2.0 * kernel.axes[d].b * libm::sin(2.0 * delta[d]));
                }
                let e = [s(i, 0) - s(j, 0), s(i, 1) - s(j, 1)];
                let kw = libm::exp(-(e[0] * e[0] + e[1] * e[1]) / (2.0 * task.width * task.width));
                for a in 0..2 {
                    w[a] += kw * s(j, 6 + a);
                    for c in 0..2 {
                        dw[a][c] += s(j, 6 + a) * kw * (-e[c] / (task.width * task.width));
                    }
                }
            }
            for a in 0..2 {
                let dk = w[a] - (s(i, 2 + 2 * a) * v[0] + s(i, 3 + 2 * a) * v[1]);
                let dp = -(dw[0][a] * s(i, 6) + dw[1][a] * s(i, 7)) - div * s(i, 6 + a);
                let (got_k, got_p) = (rates[8 * i + a] as f64, rates[8 * i + 6 + a] as f64);
                assert!((got_k - dk).abs() < tol * (1.0 + dk.abs()), "point {i}: dk[{a}] {got_k} vs {dk}");
                assert!((got_p - dp).abs() < tol * (1.0 + dp.abs()), "point {i}: dP[{a}] {got_p} vs {dp}");
            }
        }
        // The control points integrate with it (Heun × 2), every stage's state finite.
        let integrator = Integrator { method: IntegratorMethod::Heun, steps: 2 };
        let (mut scratch, mut trajectory) = ([0.0 as Real; 8 * COUNT * 8], [0.0 as Real; 6 * COUNT * 4]);
        let mut stages = 0;
        integrate_control_points(&params, integrator, &points, &mut state, &mut scratch, &mut trajectory, |_, y| {
            assert!(y.iter().all(|v| v.is_finite()));
            stages += 1;
        })
        .unwrap();
        assert_eq!(stages, 4);
        assert!(state.iter().all(|v| v.is_finite()));
    }
}
