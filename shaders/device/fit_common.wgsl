
// Shared by the kernels of the fitting loop (`src/gpu/fit.rs`); the host prepends it.
//
// A Gaussian's parameters are STRIDE floats, in the stored parameterization the CPU
// fitter moves (`fit::params`): centre (u, v) in image units, ln σ1, ln σ2, θ (or, for
// a decoded scene, whichever covariance parameters it stores), colour (r, g, b),
// opacity. The Adam moments use the same layout.

// STRIDE, and GROUP (invocations per workgroup of every one-dimensional kernel), come
// with the contract constants, from the host's own.

// One uniform block for the whole loop, rewritten by the host before each step.
struct Fit {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    // Gaussians.
    count: u32,
    // Tile-list entries the buffers hold.
    capacity: u32,
    // 0 = sum, 1 = alpha.
    blend: u32,
    has_opacity: u32,
    // Render the quantized parameters (quantization-aware fine-tuning).
    qat: u32,
    bits_position: u32,
    bits_covariance: u32,
    bits_color: u32,
    bits_opacity: u32,
    // The angle of a log-scale-rotation covariance (its range is a quarter turn); the
    // host sets bits_covariance here for a Cholesky factor.
    bits_angle: u32,
    lr_position: f32,
    lr_log_scale: f32,
    lr_rotation: f32,
    lr_color: f32,
    lr_opacity: f32,
    // Adam's bias corrections for this step, 1 - β^t.
    c1: f32,
    c2: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    // The parameters are a Cholesky factor (l11, l21, l22) rather than ln σ1, ln σ2, θ
    // (a decoded scene's choice; the fitter always moves log-scale-rotation).
    cholesky: u32,
    // A uniform block is a whole number of 16-byte rows.
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> fit: Fit;

// θ reduced to [-π, π], where Vulkan, Metal and DX12 bound the error of `sin` and `cos`
// (outside it they promise nothing; lavapipe happens to reduce exactly). Inside that
// range it returns θ itself, bit for bit, so the CPU's figures are unchanged there.
fn wrap_angle(th: f32) -> f32 {
    let tau = 6.2831855;
    return th - tau * round(th / tau);
}

// `CovParam::LogScaleRotation.covariance`: Σ = R diag(σ1², σ2²) Rᵀ in image units, as
// (Σuu, Σuv, Σvv), σ = exp of the clamped log-scale. The projection and the chain rule
// both take it from here, so the clamps they test see the same numbers.
fn lsr_covariance(l1: f32, l2: f32, th: f32) -> vec3<f32> {
    let s1 = exp(clamp(l1, LN_SIGMA_MIN, LN_SIGMA_MAX));
    let s2 = exp(clamp(l2, LN_SIGMA_MIN, LN_SIGMA_MAX));
    let sn = sin(wrap_angle(th));
    let cs = cos(wrap_angle(th));
    let v1 = s1 * s1;
    let v2 = s2 * s2;
    return vec3<f32>(cs * cs * v1 + sn * sn * v2, sn * cs * (v1 - v2), sn * sn * v1 + cs * cs * v2);
}
