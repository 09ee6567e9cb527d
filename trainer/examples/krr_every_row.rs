//! The kernel-ridge peer's evidence on a subset against every row (issue 38 item 5; BENCHMARKS.md): on
//! the noisy RR benchmark (`cbd bench --evidence-sizes`' data: √N × √N grid, σ = 1e-4, noise seed 0x5eee
//! unless given — `cbd simulate --seed S` draws with S + 0x5eed;
//! 3000 random noise-free test configurations, seed 7), its choice on `max_points` evenly spaced rows
//! (the kernel form; the weight space declined) and that choice refined on every row (the weight space),
//! each with its profiled log marginal likelihood on every row recomputed in the kernel form (an
//! independent check of the weight space's value and of what the refinement gained), and its test error.
//! With STEP, also the kernel form on every row at ± STEP in each log coordinate around the refined
//! choice: is it a maximum there? With `kernel`, also the kernel form's own search (grid and pattern
//! search) on every row, as a reference for the basin (O(N³) per evaluation: minutes at N = 4096).
//!
//!     cargo run --release -p cbd-trainer --example krr_every_row -- PER_AXIS [NOISE_SEED|-] [STEP|-] [kernel]

#[path = "support/rr_prior.rs"]
mod rr_prior;

use cbd_protocol::{JointKernel, JointKernelAxis};
use cbd_trainer::baselines::kernel_ridge::selection::{normalised_residual, profiled_lml};
use cbd_trainer::baselines::kernel_ridge::{
    choose_kernel_ridge_hyperparameters, kernel_matrix, Hyperparameters, KernelRidge, SearchOptions,
};
use cbd_trainer::simulate::rr;

/// (ln b_1, ln b_2, ln ν) of a choice, ν = σ²/γ.
fn packed(h: &Hyperparameters) -> Vec<f64> {
    let b = h.kernel.axes.iter().map(|a| if let JointKernelAxis::Periodic { b } = a { b.ln() } else { f64::NAN });
    b.chain([(h.ridge() / h.kernel.gamma).ln()]).collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let per_axis: usize = args.get(1).map_or(64, |s| s.parse().expect("PER_AXIS"));
    let noise_seed: u64 = args.get(2).filter(|s| *s != "-").map_or(1u64.wrapping_add(0x5eed), |s| s.parse().expect("NOISE_SEED"));
    let step: Option<f64> = args.get(3).filter(|s| *s != "-").map(|s| s.parse().expect("STEP"));
    let kernel_form_too = args.get(4).is_some_and(|s| s == "kernel");
    let (_, noisy, test) = rr_prior::benchmark(per_axis, noise_seed);
    let nominal = rr::nominal();
    let scale = noisy.normalisation().task_scale;
    let residual = normalised_residual(&nominal, &noisy, scale);
    // The kernel form's profiled log marginal likelihood on every row at (ln b_d, ln ν).
    let every_row = |p: &[f64]| {
        let axes = p[..2].iter().map(|lb| JointKernelAxis::Periodic { b: lb.exp() });
        let unit = JointKernel { gamma: 1.0, axes: heapless::Vec::from_iter(axes) };
        profiled_lml(&kernel_matrix(&unit, &noisy.joints, &noisy.joints, 2), &residual, p[2].exp()).map_or(f64::NAN, |v| v.0)
    };
    let subset_only = SearchOptions { max_weight_space_weights: 0, ..SearchOptions::default() };
    let mut runs = vec![("subset", subset_only), ("every row", SearchOptions::default())];
    if kernel_form_too {
        runs.insert(1, ("kernel form on every row", SearchOptions { max_points: usize::MAX, ..SearchOptions::default() }));
    }
    let mut refined_at = Vec::new();
    for (name, options) in runs {
        let t0 = std::time::Instant::now();
        let h = choose_kernel_ridge_hyperparameters(&nominal, &noisy, &options).unwrap();
        let seconds = t0.elapsed().as_secs_f64();
        let krr = KernelRidge::fit(&nominal, &noisy, h.kernel.clone(), h.ridge()).unwrap();
        let test_mean = rr_prior::mean_error(&krr.predict(&nominal, &test.joints), &test.positions);
        let p = packed(&h);
        println!(
            "{name}: {} ({seconds:.2} s)\n  on every row, kernel form: lml {:.3}; test mean {test_mean:.4e}",
            cbd_trainer::baselines::kernel_ridge::correction::describe(&h),
            every_row(&p)
        );
        refined_at = p;
    }
    if let Some(step) = step {
        for k in 0..refined_at.len() {
            for dir in [-1.0, 1.0] {
                let mut q = refined_at.clone();
                q[k] += dir * step;
                println!("  θ[{k}] {:+}: lml {:.3}", dir * step, every_row(&q));
            }
        }
    }
}
