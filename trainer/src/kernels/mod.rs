//! Kernels and hyperparameters: the linearised (Gaussian-process) model of DESIGN.md §3.
