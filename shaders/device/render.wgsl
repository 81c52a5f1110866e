// Forward rasterization of projected 2D Gaussians: one workgroup per 16×16 tile, one
// invocation per pixel, the tile's Gaussians visited in stored order.
//
// This is format-spec.md §6.3–6.4, the same per-pixel rule as the CPU renderer
// (`Projected::alpha_at` and `render::cpu`), evaluated in f32 in the same order, with the
// spec's `exp` (`spec_exp`, prepended by the host). A GPU compiler may fuse a product and
// a sum, which is why GPU and CPU are held to 1/255 rather than to the same bits. Projection (covariance clamps, conic, pixel box) and binning come
// from the CPU's `render::project` (`Gpu::render`), or from `fit_project.wgsl` and the
// radix sort (the resident pipeline of `gpu::forward`).
//
// Every pixel of a tile reads the same Gaussians, so the workgroup fetches them together,
// a batch of BATCH at a time, into workgroup memory (one global read per Gaussian and
// tile instead of one per pixel), and every pixel then reads each from there. In `alpha`
// blending the workgroup stops once no pixel of the tile is still accumulating.
//
// The contract constants (TILE, ALPHA_MIN, …) are prepended by the host, written from the
// Rust constants (`gpu::contract`).

struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    // 0 = sum, 1 = alpha (spec §6.4)
    blend: u32,
    // First tile row of this band; its output starts at pixel row `tile_row0 * TILE`.
    tile_row0: u32,
    // Pixel rows in this band's output.
    rows: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Three vec4 per Gaussian: (mx, my, A, B), (C, opacity, r, g), (b, …); the lanes after
// b are not read here.
@group(0) @binding(1) var<storage, read> gaussians: array<vec4<f32>>;
// Pixel box per Gaussian: (x0, y0, x1, y1), inclusive.
@group(0) @binding(2) var<storage, read> boxes: array<vec4<u32>>;
// Tile t of the band lists indices[offsets[t] .. offsets[t + 1]].
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
@group(0) @binding(4) var<storage, read> indices: array<u32>;
// RGB per pixel of the band, row-major.
@group(0) @binding(5) var<storage, read_write> out_rgb: array<f32>;

// One Gaussian per invocation of the workgroup: 52 bytes each, 13 KiB in all (WebGPU
// guarantees 16 KiB).
const BATCH: u32 = TILE * TILE;
var<workgroup> batch_box: array<vec4<u32>, BATCH>;
var<workgroup> batch_centre_ab: array<vec4<f32>, BATCH>;
var<workgroup> batch_c_opacity_rg: array<vec4<f32>, BATCH>;
var<workgroup> batch_blue: array<f32, BATCH>;
// The tile's list, [first, last).
var<workgroup> list: vec2<u32>;
// Pixels of the tile still accumulating, and its value as the workgroup last read it.
var<workgroup> live: atomic<u32>;
var<workgroup> live_read: u32;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = wg.x * TILE + lid.x;
    let band_row = wg.y * TILE + lid.y;
    let j = params.tile_row0 * TILE + band_row;
    // Invocations past the image's edge still fetch their share of each batch.
    let inside = i < params.width && band_row < params.rows && j < params.height;
    if (li == 0u) {
        let tile = wg.y * params.tiles_x + wg.x;
        list = vec2<u32>(offsets[tile], offsets[tile + 1u]);
        atomicStore(&live, 0u);
    }
    workgroupBarrier();
    // Only `alpha` blending stops early, so only it counts the pixels still
    // accumulating: in `sum` every pixel of a tile adding to one counter was the same
    // address written 256 times over.
    let stops = params.blend != 0u;
    if (stops && inside) {
        atomicAdd(&live, 1u);
    }
    let range = workgroupUniformLoad(&list);
    let cx = f32(i) + 0.5;
    let cy = f32(j) + 0.5;
    var acc = vec3<f32>(0.0, 0.0, 0.0);
    var t = 1.0;
    var accumulating = inside;
    for (var base = range.x; base < range.y; base = base + BATCH) {
        let k = base + li;
        if (k < range.y) {
            let g = indices[k];
            batch_box[li] = boxes[g];
            batch_centre_ab[li] = gaussians[3u * g];
            batch_c_opacity_rg[li] = gaussians[3u * g + 1u];
            batch_blue[li] = gaussians[3u * g + 2u].x;
        }
        workgroupBarrier();
        if (accumulating) {
            let n = min(BATCH, range.y - base);
            for (var s = 0u; s < n; s = s + 1u) {
                let b = batch_box[s];
                if (i < b.x || i > b.z || j < b.y || j > b.w) {
                    continue;
                }
                let p0 = batch_centre_ab[s];
                let p1 = batch_c_opacity_rg[s];
                let dx = cx - p0.x;
                let dy = cy - p0.y;
                let power = -0.5 * (p0.z * dx * dx + p1.x * dy * dy) - p0.w * dx * dy;
                if (power > 0.0) {
                    continue;
                }
                var alpha = p1.y * spec_exp(power);
                let color = vec3<f32>(p1.z, p1.w, batch_blue[s]);
                if (params.blend == 0u) {
                    if (alpha < ALPHA_MIN) {
                        continue;
                    }
                    acc = acc + color * alpha;
                } else {
                    alpha = min(alpha, ALPHA_MAX);
                    if (alpha < ALPHA_MIN) {
                        continue;
                    }
                    acc = acc + color * alpha * t;
                    t = t * (1.0 - alpha);
                    if (t < TRANSMITTANCE_MIN) {
                        accumulating = false;
                        atomicSub(&live, 1u);
                        break;
                    }
                }
            }
        }
        // Every pixel is done with this batch before the next overwrites it, and every
        // pixel that stopped has said so before the count is read.
        workgroupBarrier();
        if (stops) {
            if (li == 0u) {
                live_read = atomicLoad(&live);
            }
            if (workgroupUniformLoad(&live_read) == 0u) {
                break;
            }
        }
    }
    if (inside) {
        let o = 3u * (band_row * params.width + i);
        out_rgb[o] = acc.x;
        out_rgb[o + 1u] = acc.y;
        out_rgb[o + 2u] = acc.z;
    }
}
