use super::*;
extern crate std;

fn rot_axis_angle(axis: V3, angle: f64) -> [V3; 3] {
    let n = libm::sqrt(dot(axis, axis));
    let half = 0.5 * angle;
    let s = libm::sin(half) / n;
    quaternion_rotation([libm::cos(half), axis[0] * s, axis[1] * s, axis[2] * s])
}

fn apply(r: &[V3; 3], t: V3, p: V3) -> V3 {
    add_v(rotate(r, p), t)
}

const NOMINAL: [V3; 3] = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]];

fn close(a: &[V3; 3], b: &[V3; 3]) -> f64 {
    a.iter().flatten().zip(b.iter().flatten()).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

#[test]
fn a_known_rotation_is_recovered_exactly_from_noise_free_points() {
    let mut worst: f64 = 0.0;
    for (axis, angle) in [
        ([0.3, -0.5, 0.8], 0.7),
        ([1.0, 0.0, 0.0], core::f64::consts::PI - 1e-9),
        ([0.0, 0.0, 1.0], 1e-12),
        ([-0.2, 0.9, 0.1], -2.5),
        ([1.0, 1.0, 1.0], 0.0),
    ] {
        let r = rot_axis_angle(axis, angle);
        let t = [812.0, -44.5, 1310.25];
        for nominal in [&NOMINAL[..], &[[0.0, 0.0, 31.0], [100.0, 0.0, 31.0], [0.0, 100.0, 31.0], [50.0, 40.0, -20.0]][..]] {
            let measured: std::vec::Vec<V3> = nominal.iter().map(|p| apply(&r, t, *p)).collect();
            let fit = fit_frame(nominal, &measured).unwrap();
            worst = worst.max(close(&fit.rotation, &r));
            for (a, b) in fit.origin.iter().zip(t) {
                assert!((a - b).abs() < 1e-9, "origin {a} vs {b}");
            }
            assert!(fit.residual < 1e-10, "residual {}", fit.residual);
            // The rotation is orthonormal with det +1.
            let rrt = relative_rotation(&fit.rotation, &fit.rotation);
            assert!(close(&rrt, &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) < 1e-14);
            assert!((dot(fit.rotation[0], cross(fit.rotation[1], fit.rotation[2])) - 1.0).abs() < 1e-14);
        }
    }
    std::eprintln!("noise-free recovery: worst |R − R_true| {worst:.1e}");
    assert!(worst < 1e-13);
}

#[test]
fn with_noise_the_fit_is_the_least_squares_one() {
    // Noisy points: the fit's objective is not lowered by any small rotation or translation.
    let r = rot_axis_angle([0.2, 0.4, -0.9], 1.1);
    let t = [10.0, 20.0, 30.0];
    let nominal = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0], [30.0, 30.0, 50.0]];
    let noise = [[0.02, -0.01, 0.03], [-0.02, 0.015, 0.0], [0.01, 0.02, -0.03], [-0.01, -0.02, 0.01]];
    let measured: std::vec::Vec<V3> = nominal.iter().zip(noise).map(|(p, e)| add_v(apply(&r, t, *p), e)).collect();
    let fit = fit_frame(&nominal, &measured).unwrap();
    let cost = |rr: &[V3; 3], tt: V3| -> f64 {
        nominal
            .iter()
            .zip(&measured)
            .map(|(p, y)| {
                let e = sub(apply(rr, tt, *p), *y);
                dot(e, e)
            })
            .sum()
    };
    let best = cost(&fit.rotation, fit.origin);
    assert!((libm::sqrt(best / 4.0) - fit.residual).abs() < 1e-12);
    for k in 0..3 {
        for sign in [-1.0, 1.0] {
            let mut axis = ZERO;
            axis[k] = 1.0;
            let turned = relative_rotation(&rot_axis_angle(axis, sign * 1e-5), &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
            // R' = exp(ε e_k) R
            let mut rp = [[0.0; 3]; 3];
            for (i, row) in rp.iter_mut().enumerate() {
                for (j, v) in row.iter_mut().enumerate() {
                    *v = (0..3).map(|l| turned[i][l] * fit.rotation[l][j]).sum();
                }
            }
            assert!(cost(&rp, fit.origin) >= best, "rotation {k} {sign}");
            let mut tt = fit.origin;
            tt[k] += sign * 1e-5;
            assert!(cost(&fit.rotation, tt) >= best, "translation {k} {sign}");
        }
    }
}

#[test]
fn fewer_than_three_or_collinear_points_are_refused() {
    assert!(fit_frame(&NOMINAL[..2], &NOMINAL[..2]).is_none());
    let line = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [250.0, 0.0, 0.0]];
    assert!(!determines_orientation(&line));
    assert!(fit_frame(&line, &line).is_none());
    let same = [[1.0, 2.0, 3.0]; 3];
    assert!(fit_frame(&same, &same).is_none());
    assert!(fit_frame(&NOMINAL, &NOMINAL[..2]).is_none());
    let mut nan = NOMINAL;
    nan[1][0] = f64::NAN;
    assert!(fit_frame(&NOMINAL, &nan).is_none());
    assert!(determines_orientation(&NOMINAL));
}

#[test]
fn the_frame_velocity_matches_finite_differences() {
    let r = rot_axis_angle([0.3, -0.5, 0.8], 0.7);
    let t = [812.0, -44.5, 1310.25];
    let nominal = [[5.0, 0.0, 31.0], [100.0, 0.0, 31.0], [0.0, 100.0, 31.0]];
    // Non-rigid points (a deformation on top), moving along arbitrary velocities.
    let base: std::vec::Vec<V3> =
        nominal.iter().enumerate().map(|(j, p)| add_v(apply(&r, t, *p), [0.1 * j as f64, -0.05, 0.02 * j as f64])).collect();
    let velocity = [[1.0, -2.0, 0.5], [0.3, 0.7, -1.1], [-0.4, 0.2, 0.9]];
    let at_h = |h: f64| -> FrameFit {
        let moved: std::vec::Vec<V3> = base.iter().zip(velocity).map(|(y, v)| add_v(*y, scale(v, h))).collect();
        fit_frame(&nominal, &moved).unwrap()
    };
    let fit = at_h(0.0);
    let (dt, omega) = frame_velocity(&fit, &nominal, &base, &velocity).unwrap();
    let h = 1e-6;
    let (plus, minus) = (at_h(h), at_h(-h));
    let fd_t: V3 = core::array::from_fn(|a| (plus.origin[a] - minus.origin[a]) / (2.0 * h));
    let fd_omega = scale(rotation_vector(&relative_rotation(&plus.rotation, &minus.rotation)), 1.0 / (2.0 * h));
    for a in 0..3 {
        assert!((fd_t[a] - dt[a]).abs() < 1e-6, "dt[{a}] {} vs {}", fd_t[a], dt[a]);
        assert!((fd_omega[a] - omega[a]).abs() < 1e-8, "omega[{a}] {} vs {}", fd_omega[a], omega[a]);
    }
}

#[test]
fn the_rotation_vector_inverts_the_exponential() {
    for (axis, angle) in
        [([0.3, -0.5, 0.8], 0.7), ([1.0, 0.0, 0.0], 1e-9), ([0.0, 1.0, 1.0], 3.1), ([0.2, 0.1, -1.0], core::f64::consts::PI - 1e-7)]
    {
        let r = rot_axis_angle(axis, angle);
        let v = rotation_vector(&r);
        let n = libm::sqrt(dot(axis, axis));
        for a in 0..3 {
            assert!((v[a] - axis[a] / n * angle).abs() < 1e-9, "{axis:?} {angle}: {v:?}");
        }
    }
}
