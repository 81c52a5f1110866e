// The constants of the pixel contract (format-spec.md §6), shared by every shader: the
// host prepends this file to each one (`src/gpu/mod.rs`), since WGSL has no includes.
// They must equal `render::TILE`, `ALPHA_MIN`, `ALPHA_MAX` and `TRANSMITTANCE_MIN`.

const TILE: u32 = 16u;
const ALPHA_MIN: f32 = 0.003921569; // 1/255
const ALPHA_MAX: f32 = 0.99;
const TRANSMITTANCE_MIN: f32 = 0.0001;
