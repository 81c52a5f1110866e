
// Shared by the kernels of stage 2's mixture on the GPU (`enhance::gpu`, in
// crates/enhance); the host prepends it. They evaluate what `enhance::fit` evaluates per Gaussian: the mixing
// weights from the map, the K - 1 operator MLPs, and their backward pass. The image
// side of an iteration (the render A·c, the loss, Aᵀ) stays on the CPU.
//
// A Gaussian's record in `gauss` is GAUSS u32s: the four map cells of its tap, their
// four weights and its colour (f32 bits), and one unused word. GAUSS, and WIDTH_MAX (the
// largest K and hidden width, the private arrays' length), are written ahead of this file
// from the host's own constants (`enhance::gpu::layout`).

struct Mix {
    // Gaussians.
    count: u32,
    // K, operator 0 being the identity.
    experts: u32,
    hidden: u32,
    // Parameters of one operator: W1 (3h), b1 (h), W2 (h²), b2 (h), W3 (h), b3 (1).
    per: u32,
    // The operators' output clamp.
    lo: f32,
    hi: f32,
    // `GAIN_LOG_MAX`. The shaders take its exponential themselves, so that the gain clamp
    // compares numbers computed on one device (a CPU `exp` beside a GPU one can differ
    // by an ulp and give a saturated operator a gradient the CPU gives none).
    gain_log_max: f32,
    // Gaussians per partial sum (`enhance::fit::CHUNK`).
    chunk: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    _pad3: u32,
}

@group(0) @binding(0) var<uniform> shape: Mix;

// Where operator op's tensors start in `params` (`Enhancer::operator`'s layout).
struct Tensors {
    w1: u32,
    b1: u32,
    w2: u32,
    b2: u32,
    w3: u32,
    b3: u32,
}

fn tensors(op: u32) -> Tensors {
    let h = shape.hidden;
    let w1 = (op - 1u) * shape.per;
    let b1 = w1 + 3u * h;
    let w2 = b1 + h;
    let b2 = w2 + h * h;
    let w3 = b2 + h;
    return Tensors(w1, b1, w2, b2, w3, w3 + h);
}

fn color0(g: u32) -> vec3<f32> {
    let b = GAUSS * g + 8u;
    return vec3<f32>(bitcast<f32>(gauss[b]), bitcast<f32>(gauss[b + 1u]), bitcast<f32>(gauss[b + 2u]));
}

// Where the forward pass leaves a Gaussian's activations in `trace`: the K mixing
// weights of every Gaussian, then the two hidden layers' pre-activations of every
// (Gaussian, operator), then the unclamped outputs (3 each).
fn trace_w(g: u32) -> u32 {
    return g * shape.experts;
}
fn trace_h1(g: u32, op: u32) -> u32 {
    return shape.count * shape.experts + (g * (shape.experts - 1u) + op - 1u) * shape.hidden;
}
fn trace_h2(g: u32, op: u32) -> u32 {
    return trace_h1(g, op) + shape.count * (shape.experts - 1u) * shape.hidden;
}
fn trace_raw(g: u32, op: u32) -> u32 {
    return shape.count * (shape.experts + 2u * (shape.experts - 1u) * shape.hidden)
        + (g * (shape.experts - 1u) + op - 1u) * 3u;
}

// Where the per-Gaussian backward pass leaves, per (Gaussian, operator), the gradient of
// the log-gain η and of the two hidden layers' pre-activations, in `back`.
fn back_eta(g: u32, op: u32) -> u32 {
    return g * (shape.experts - 1u) + op - 1u;
}
fn back_g1(g: u32, op: u32) -> u32 {
    return shape.count * (shape.experts - 1u) + (g * (shape.experts - 1u) + op - 1u) * shape.hidden;
}
fn back_g2(g: u32, op: u32) -> u32 {
    return back_g1(g, op) + shape.count * (shape.experts - 1u) * shape.hidden;
}

// The (Gaussian, operator) an invocation of a per-operator kernel handles, or none
// (x = count) past the last or when there are no operators.
fn gaussian_and_operator(id: u32) -> vec2<u32> {
    let ops = shape.experts - 1u;
    if (ops == 0u || id >= shape.count * ops) {
        return vec2<u32>(shape.count, 0u);
    }
    return vec2<u32>(id / ops, id % ops + 1u);
}

// Operator op's unclamped output for Gaussian g, from the trace (each kernel that reads
// it declares `trace`).
fn output(g: u32, op: u32) -> vec3<f32> {
    let tr = trace_raw(g, op);
    return vec3<f32>(trace[tr], trace[tr + 1u], trace[tr + 2u]);
}

// An operator's output as the clamp of `Enhancer::operator` leaves it.
fn clamped(raw: vec3<f32>) -> vec3<f32> {
    return min(max(raw, vec3<f32>(shape.lo)), vec3<f32>(shape.hi));
}
