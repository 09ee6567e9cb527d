use super::*;
use cbd_protocol::*;

fn small_problem(law: MomentumLaw, method: IntegratorMethod) -> (ControlPoints, Vec<f64>) {
    let nominal = crate::simulate::rr::nominal();
    let points: Vec<f64> = crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 7, seed: 3 }, 2);
    let cp = ControlPoints::new(
        &nominal,
        &Normalisation::IDENTITY,
        points,
        cbd_protocol::paper_rr::joint_kernel(),
        cbd_protocol::paper_rr::task_kernel(),
        law,
        Integrator { method, steps: 3 },
    );
    let p0: Vec<f64> = (0..14).map(|k| 0.02 * ((k * 37 % 11) as f64 - 5.0)).collect();
    (cp, p0)
}

/// Largest |central difference − tangent| / (1 + |difference|) over the positions' Jacobian at `p0`.
fn worst_against_finite_differences(cp: &ControlPoints, p0: &[f64]) -> f64 {
    let jac = position_jacobian(cp, &cp.integrate(p0).unwrap(), 2);
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    for dir in 0..p0.len() {
        let (mut pa, mut pb) = (p0.to_vec(), p0.to_vec());
        pa[dir] += h;
        pb[dir] -= h;
        let ya = cp.integrate(&pa).unwrap().positions(cp.dims);
        let yb = cp.integrate(&pb).unwrap().positions(cp.dims);
        for r in 0..ya.len() {
            let fd = (ya[r] - yb[r]) / (2.0 * h);
            worst = worst.max((fd - jac[(r, dir)]).abs() / (1.0 + fd.abs()));
        }
    }
    worst
}

#[test]
fn tangent_matches_central_finite_differences() {
    for law in
        [MomentumLaw::WithDivergence, MomentumLaw::WithoutDivergence, MomentumLaw::Hamiltonian, MomentumLaw::HamiltonianWithoutDivergence]
    {
        for method in [IntegratorMethod::Euler, IntegratorMethod::Heun, IntegratorMethod::Rk4] {
            let (cp, p0) = small_problem(law, method);
            let worst = worst_against_finite_differences(&cp, &p0);
            assert!(worst < 1e-7, "{law:?} {method:?}: worst relative difference {worst:e}");
        }
    }
}

/// The evidence's kind of kernels: one nearly flat periodic axis, a wide task kernel, a
/// normalised task space, momenta of the size a noise-free fit gives. Euler × 2, Hamiltonian.
#[test]
fn tangent_matches_finite_differences_for_wide_kernels_and_normalised_task_space() {
    let nominal = crate::simulate::rr::nominal();
    let points: Vec<f64> = crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 9, seed: 5 }, 2);
    let mut norm = Normalisation::IDENTITY;
    norm.task_scale = 1.18;
    norm.task_offset[0] = 0.3;
    norm.task_offset[1] = -0.2;
    for (b, width, scale) in [([0.0045, 0.106], 2.16, 1.0), ([0.0045, 0.106], 2.16, 30.0), ([1.0186, 1.0186], 3.0, 10.0)] {
        let cp = ControlPoints::new(
            &nominal,
            &norm,
            points.clone(),
            JointKernel {
                gamma: 0.26,
                axes: heapless::Vec::from_slice(&[JointKernelAxis::Periodic { b: b[0] }, JointKernelAxis::Periodic { b: b[1] }]).unwrap(),
            },
            TaskKernel { width },
            MomentumLaw::Hamiltonian,
            Integrator { method: IntegratorMethod::Euler, steps: 2 },
        );
        let p0: Vec<f64> = (0..18).map(|k| scale * 0.02 * ((k * 37 % 11) as f64 - 5.0)).collect();
        let worst = worst_against_finite_differences(&cp, &p0);
        assert!(worst < 1e-6, "b {b:?} width {width} momenta ×{scale}: worst relative difference {worst:e}");
    }
}

#[test]
fn jacobian_along_directions_is_the_jacobian_times_them() {
    let (cp, p0) = small_problem(MomentumLaw::WithDivergence, IntegratorMethod::Heun);
    let flow = cp.integrate(&p0).unwrap();
    let jac = position_jacobian(&cp, &flow, 2);
    let dirs = Mat::from_fn(14, 5, |r, c| ((r * 7 + c * 3) % 11) as f64 / 11.0 - 0.5);
    let along = super::super::with_threads(2, || position_jacobian_along(&cp, &flow, dirs.as_ref()));
    let mut worst: f64 = 0.0;
    for c in 0..5 {
        for r in 0..14 {
            let expected: f64 = (0..14).map(|k| jac[(r, k)] * dirs[(k, c)]).sum();
            worst = worst.max((along[(r, c)] - expected).abs());
        }
    }
    assert!(worst < 1e-12, "{worst:e}");
}

/// The first-stage cache gives the uncached values exactly, for every scheme (one stage:
/// nothing cached) and both momentum laws.
#[test]
fn cached_first_stage_gives_the_uncached_jacobian() {
    for law in
        [MomentumLaw::WithDivergence, MomentumLaw::WithoutDivergence, MomentumLaw::Hamiltonian, MomentumLaw::HamiltonianWithoutDivergence]
    {
        for method in [IntegratorMethod::Euler, IntegratorMethod::Heun, IntegratorMethod::Rk4] {
            let (mut cp, p0) = small_problem(law, method);
            for steps in [1, 3] {
                cp.integrator.steps = steps;
                let flow = cp.integrate(&p0).unwrap();
                let dirs = Mat::from_fn(14, 9, |r, c| ((r * 5 + c * 7) % 13) as f64 / 13.0 - 0.4);
                let (plain, cached) = super::super::with_threads(2, || {
                    (position_jacobian_along(&cp, &flow, dirs.as_ref()), TangentAlong::new(&cp, dirs.clone()).jacobian(&cp, &flow))
                });
                assert!(plain == cached, "{law:?} {method:?} × {steps}");
            }
        }
    }
}

#[test]
fn jacobian_does_not_depend_on_thread_count() {
    let (cp, p0) = small_problem(MomentumLaw::WithDivergence, IntegratorMethod::Heun);
    let flow = cp.integrate(&p0).unwrap();
    let (a, b) = (position_jacobian(&cp, &flow, 1), position_jacobian(&cp, &flow, 2));
    assert!(a == b);
}
