//! Levenberg–Marquardt on energy (16) over the initial momenta.
