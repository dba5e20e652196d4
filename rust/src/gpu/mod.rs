//! The GPU backend's Rust side: the per-point constants its kernel reads (the kernel itself is
//! CUDA C in `python/idm_rs/gpu/idm_kernel.cu`, launched from Python through CuPy).

pub mod generate;
pub mod kernel;
