//! Fixed-step explicit integrators on t ∈ [0, 1]. Training optimises exactly this discrete flow,
//! so this file is the single source of truth for the time discretisation.

use crate::real::Real;
use cbd_protocol::IntegratorMethod;

/// Scratch needed by [`integrate`] for a state of `len` values.
pub const fn scratch_len(len: usize) -> usize {
    3 * len
}

/// Advances `y` from t = 0 to t = 1 in `steps` equal steps of `method`.
///
/// `rhs(stage, y_stage, out)` is called once for every stage, in order, `stage` counting
/// from 0 to `method.stages() * steps - 1`; callers use the index to pick stored trajectories.
/// `scratch` must hold at least [`scratch_len`]`(y.len())` values: this panics otherwise
/// (the runtime itself calls [`integrate_checked`], which cannot panic).
pub fn integrate<E>(
    method: IntegratorMethod,
    steps: u16,
    y: &mut [Real],
    scratch: &mut [Real],
    rhs: impl FnMut(usize, &[Real], &mut [Real]) -> Result<(), E>,
) -> Result<(), E> {
    let len = y.len();
    let (acc, rest) = scratch.split_at_mut(len);
    let (slope, rest) = rest.split_at_mut(len);
    let (stage_state, _) = rest.split_at_mut(len);
    steps_of(method, steps, y, acc, slope, stage_state, rhs)
}

/// [`integrate`], returning `Err(short_scratch)` instead of panicking when `scratch` is shorter
/// than [`scratch_len`]`(y.len())`.
pub fn integrate_checked<E>(
    method: IntegratorMethod,
    steps: u16,
    y: &mut [Real],
    scratch: &mut [Real],
    short_scratch: E,
    rhs: impl FnMut(usize, &[Real], &mut [Real]) -> Result<(), E>,
) -> Result<(), E> {
    let len = y.len();
    let Some((acc, rest)) = scratch.split_at_mut_checked(len) else { return Err(short_scratch) };
    let Some((slope, rest)) = rest.split_at_mut_checked(len) else { return Err(short_scratch) };
    let Some((stage_state, _)) = rest.split_at_mut_checked(len) else { return Err(short_scratch) };
    steps_of(method, steps, y, acc, slope, stage_state, rhs)
}

/// The steps themselves; `acc`, `slope` and `stage_state` hold as many values as `y`.
fn steps_of<E>(
    method: IntegratorMethod,
    steps: u16,
    y: &mut [Real],
    acc: &mut [Real],
    slope: &mut [Real],
    stage_state: &mut [Real],
    mut rhs: impl FnMut(usize, &[Real], &mut [Real]) -> Result<(), E>,
) -> Result<(), E> {
    let h = 1.0 / steps as Real;
    let mut stage = 0;
    for _ in 0..steps {
        match method {
            IntegratorMethod::Euler => {
                rhs(stage, y, slope)?;
                stage += 1;
                for (yi, si) in y.iter_mut().zip(slope.iter()) {
                    *yi += h * si;
                }
            }
            // Heun: y' = y + h/2 (f(y) + f(y + h f(y)))
            IntegratorMethod::Heun => {
                rhs(stage, y, acc)?;
                for ((zi, yi), ai) in stage_state.iter_mut().zip(y.iter()).zip(acc.iter()) {
                    *zi = yi + h * ai;
                }
                rhs(stage + 1, stage_state, slope)?;
                stage += 2;
                let half = 0.5 * h;
                for ((yi, ai), si) in y.iter_mut().zip(acc.iter()).zip(slope.iter()) {
                    *yi += half * (ai + si);
                }
            }
            // Classical RK4: y' = y + h/6 (k1 + 2 k2 + 2 k3 + k4)
            IntegratorMethod::Rk4 => {
                rhs(stage, y, acc)?;
                for ((zi, yi), ai) in stage_state.iter_mut().zip(y.iter()).zip(acc.iter()) {
                    *zi = yi + 0.5 * h * ai;
                }
                rhs(stage + 1, stage_state, slope)?;
                for (((zi, yi), ai), si) in stage_state.iter_mut().zip(y.iter()).zip(acc.iter_mut()).zip(slope.iter()) {
                    *ai += 2.0 * si;
                    *zi = yi + 0.5 * h * si;
                }
                rhs(stage + 2, stage_state, slope)?;
                for (((zi, yi), ai), si) in stage_state.iter_mut().zip(y.iter()).zip(acc.iter_mut()).zip(slope.iter()) {
                    *ai += 2.0 * si;
                    *zi = yi + h * si;
                }
                rhs(stage + 3, stage_state, slope)?;
                stage += 4;
                let sixth = h / 6.0;
                for ((yi, ai), si) in y.iter_mut().zip(acc.iter()).zip(slope.iter()) {
                    *yi += sixth * (ai + si);
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    // y' = [y1, -y0] from (1, 0): the exact solution is (cos t, −sin t).
    fn rotation_error(method: IntegratorMethod, steps: u16) -> f64 {
        let mut y = [1.0, 0.0];
        let mut scratch = [0.0; 6];
        let mut calls = 0;
        integrate::<()>(method, steps, &mut y, &mut scratch, |stage, s, out| {
            assert_eq!(stage, calls);
            calls += 1;
            out[0] = s[1];
            out[1] = -s[0];
            Ok(())
        })
        .unwrap();
        assert_eq!(calls, method.stages() * steps as usize);
        libm::hypot(y[0] as f64 - libm::cos(1.0), y[1] as f64 + libm::sin(1.0))
    }

    #[test]
    #[cfg_attr(feature = "f32", ignore = "Rk4's error at 16 steps, about 1e-7, is f32's rounding")]
    fn integrators_have_their_order() {
        for (method, order) in [(IntegratorMethod::Euler, 1.0), (IntegratorMethod::Heun, 2.0), (IntegratorMethod::Rk4, 4.0)] {
            let e1 = rotation_error(method, 8);
            let e2 = rotation_error(method, 16);
            let observed = libm::log2(e1 / e2);
            assert!((observed - order).abs() < 0.15, "{method:?}: observed order {observed}");
        }
    }
}
