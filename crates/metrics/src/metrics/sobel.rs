//! The Sobel filter both stages use: one home, one order of operations.

/// Sobel responses of one image row of `C` interleaved channels (`C · width` floats),
/// given the rows above and below (edge rows replicated by the caller): a correlation
/// with `Gx = [[-1,0,1],[-2,0,2],[-1,0,1]]` and `Gy = Gxᵀ`, edge columns replicated.
/// Stage 1 places Gaussians along the grey image's edges with it (`C = 1`); stage 2's
/// spatial loss compares the RGB responses of two images (`C = 3`).
///
/// Computed in `f32` so that it vectorizes; two images go through the same code, so equal
/// images give equal responses.
pub fn sobel_row<const C: usize>(
    up: &[f32],
    mid: &[f32],
    dn: &[f32],
    gx: &mut [f32],
    gy: &mut [f32],
) {
    let n = mid.len();
    // Edge pixels: the missing neighbour is the pixel itself (C floats = 1 pixel).
    for j in (0..C.min(n)).chain(n.saturating_sub(C).max(C)..n) {
        let jm = if j >= C { j - C } else { j };
        let jp = if j + C < n { j + C } else { j };
        (gx[j], gy[j]) = sobel_taps(
            [up[jm], up[j], up[jp]],
            [mid[jm], mid[jp]],
            [dn[jm], dn[j], dn[jp]],
        );
    }
    if n <= 2 * C {
        return;
    }
    let m = n - 2 * C;
    let (ul, u0, ur) = (&up[..m], &up[C..C + m], &up[2 * C..2 * C + m]);
    let (ml, mr) = (&mid[..m], &mid[2 * C..2 * C + m]);
    let (dl, d0, dr) = (&dn[..m], &dn[C..C + m], &dn[2 * C..2 * C + m]);
    let (gx, gy) = (&mut gx[C..C + m], &mut gy[C..C + m]);
    for k in 0..m {
        (gx[k], gy[k]) = sobel_taps([ul[k], u0[k], ur[k]], [ml[k], mr[k]], [dl[k], d0[k], dr[k]]);
    }
}

/// `(Gx, Gy)` from the row above (left, centre, right), the row itself (left, right)
/// and the row below. Saturated at `±f32::MAX`, so huge inputs stay finite.
#[inline(always)]
pub fn sobel_taps(u: [f32; 3], m: [f32; 2], d: [f32; 3]) -> (f32, f32) {
    let gx = (u[2] - u[0]) + 2.0 * (m[1] - m[0]) + (d[2] - d[0]);
    let gy = (d[0] + 2.0 * d[1] + d[2]) - (u[0] + 2.0 * u[1] + u[2]);
    // Not `clamp`: that keeps NaN (∞ − ∞ from two huge inputs), `max` replaces it.
    #[allow(clippy::manual_clamp)]
    let finite = |v: f32| v.max(-f32::MAX).min(f32::MAX);
    (finite(gx), finite(gy))
}
