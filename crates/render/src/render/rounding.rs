//! `floor` and `ceil` without a call. The x86-64 baseline (SSE2) has no rounding
//! instruction, so `f64::floor` and `f32::ceil` are calls into libm there, and the
//! projection and the binning make several for every Gaussian. Below `2^52` an `f64`
//! converts to an integer and back exactly, its fraction dropped; from there one
//! comparison gives the floor or the ceiling. A NaN, an infinity or a larger value takes
//! the library's own. Every result is the library's, bit for bit, except that a negative
//! value that rounds to 0 gives +0 where the library gives −0. An `f32` goes through
//! `f64`: both conversions are exact, and so is the integer that comes back.

/// Below this magnitude an `f64` converts to an `i64` and back exactly, its fraction
/// dropped.
const EXACT: f64 = 4_503_599_627_370_496.0; // 2^52

/// `x.floor()`.
#[inline]
pub(crate) fn floor(x: f64) -> f64 {
    if x.abs() < EXACT {
        let t = x as i64 as f64;
        t - f64::from(u8::from(t > x))
    } else {
        x.floor()
    }
}

/// `x.ceil()`.
#[inline]
pub(crate) fn ceil(x: f64) -> f64 {
    if x.abs() < EXACT {
        let t = x as i64 as f64;
        t + f64::from(u8::from(t < x))
    } else {
        x.ceil()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every class of input against the library, by value (a zero's sign aside), in
    /// `f64` and through it from `f32`.
    #[test]
    fn floor_and_ceil_are_the_librarys() {
        let mut xs = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            2.999_999_8,
            -2.999_999_8,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            -8_388_608.0,
            1e30,
            -1e30,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        let mut state = 0x9E37_79B9u32;
        for _ in 0..200_000 {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let x = f32::from_bits(state);
            if x.is_finite() {
                xs.push(x);
                xs.push(x % 20_000_000.0);
            }
        }
        for k in -300i32..300 {
            for d in [-1e-3f32, -1e-7, 0.0, 1e-7, 1e-3] {
                xs.push(k as f32 + d);
            }
        }
        for &x in &xs {
            assert_eq!(floor(f64::from(x)) as f32, x.floor(), "floor {x:e}");
            assert_eq!(ceil(f64::from(x)) as f32, x.ceil(), "ceil {x:e}");
            let x = f64::from(x) * 1.000_000_1;
            assert_eq!(floor(x), x.floor(), "floor {x:e}");
            assert_eq!(ceil(x), x.ceil(), "ceil {x:e}");
        }
        assert!(floor(f64::NAN).is_nan() && ceil(f64::NAN).is_nan());
        for x in [
            4_503_599_627_370_495.5f64,
            -4_503_599_627_370_495.5,
            1e300,
            -1e300,
        ] {
            assert_eq!(floor(x), x.floor(), "floor {x:e}");
            assert_eq!(ceil(x), x.ceil(), "ceil {x:e}");
        }
    }
}
