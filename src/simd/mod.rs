//! SIMD kernels (the `wide` crate: AVX-512, AVX or plain-array fallbacks, chosen at compile time).

pub mod packet;
