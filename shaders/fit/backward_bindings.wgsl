
// Inputs and output shared by both backward passes (`backward_sum.wgsl`,
// `backward_alpha.wgsl`); the host prepends this file to each.

// SLOT, the floats of a tile-list entry's gradient (d mean (2), d conic (3), d opacity,
// d colour (3)), comes with the contract constants.

struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Three vec4 per Gaussian: (mx, my, A, B), (C, opacity, r, g), (b, …); the lanes after
// b are not read here.
@group(0) @binding(1) var<storage, read> gaussians: array<vec4<f32>>;
// Pixel box per Gaussian: (x0, y0, x1, y1), inclusive.
@group(0) @binding(2) var<storage, read> boxes: array<vec4<u32>>;
// Tile t lists indices[offsets[t] .. offsets[t + 1]], in stored order.
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
@group(0) @binding(4) var<storage, read> indices: array<u32>;
// d loss / d pixel, RGB per pixel of the whole image.
@group(0) @binding(5) var<storage, read> dl_dimage: array<f32>;
@group(0) @binding(6) var<storage, read_write> slots: array<f32>;
