//! lemi-gpu: everything that talks to the GPU through wgpu.
