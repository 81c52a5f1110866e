//! The reconstruction loss and its gradient with respect to the rendered image.

use gsi_metrics::metrics::{self, LossWorkspace, Rgb8};

/// Which loss the fitter minimizes.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Loss {
    /// `(1 − λ)·L1 + λ·(1 − MS-SSIM)`, the paper's Eq. 9. MS-SSIM uses as many scales
    /// as the image allows (plain SSIM below 22 px); below 11 px only L1 is left.
    L1MsSsim { lambda: f32 },
    /// Mean squared error: what PSNR measures.
    L2,
}

/// A loss with the buffers its gradient needs, kept between iterations.
pub struct LossFn {
    kind: Loss,
    workspace: LossWorkspace<f32>,
    ms_grad: Vec<f32>,
}

impl LossFn {
    pub fn new(kind: Loss) -> LossFn {
        LossFn {
            kind,
            workspace: LossWorkspace::new(),
            ms_grad: Vec::new(),
        }
    }

    pub fn kind(&self) -> Loss {
        self.kind
    }

    /// Loss value and `dL/dimage` for interleaved RGB images in `[0, 1]`.
    pub fn eval(
        &mut self,
        image: &[f32],
        target: &[f32],
        width: u32,
        height: u32,
    ) -> (f32, Vec<f32>) {
        let n = image.len() as f32;
        match self.kind {
            Loss::L2 => {
                let mut value = 0f64;
                let grad = image
                    .iter()
                    .zip(target)
                    .map(|(x, y)| {
                        let d = x - y;
                        value += f64::from(d * d);
                        2.0 * d / n
                    })
                    .collect();
                ((value / f64::from(n)) as f32, grad)
            }
            Loss::L1MsSsim { lambda } => {
                self.ms_grad.resize(image.len(), 0.0);
                let ms = self
                    .workspace
                    .ms_ssim_loss_grad(image, target, width, height, &mut self.ms_grad)
                    .ok();
                let lambda = if ms.is_some() { lambda } else { 0.0 };
                let mut l1 = 0f64;
                let mut grad: Vec<f32> = image
                    .iter()
                    .zip(target)
                    .map(|(x, y)| {
                        let d = x - y;
                        l1 += f64::from(d.abs());
                        (1.0 - lambda) * d.signum() * f32::from(d != 0.0) / n
                    })
                    .collect();
                if lambda > 0.0 {
                    for (a, b) in grad.iter_mut().zip(&self.ms_grad) {
                        *a += lambda * b;
                    }
                }
                (
                    (1.0 - lambda) * (l1 / f64::from(n)) as f32 + lambda * ms.unwrap_or(0.0),
                    grad,
                )
            }
        }
    }
}

/// PSNR (dB) of two images in `[0, 1]` as a decoder shows them: each channel rounded to
/// 8 bits by the rule of spec §6.5, then [`metrics::psnr`]. Infinite when they agree.
pub fn psnr8(image: &[f32], target: &[f32], width: u32, height: u32) -> f64 {
    let q = |v: &[f32]| {
        v.iter()
            .map(|&c| (c.clamp(0.0, 1.0) * 255.0 + 0.5).floor() as u8)
            .collect::<Vec<u8>>()
    };
    let (a, b) = (q(image), q(target));
    match (Rgb8::new(width, height, &a), Rgb8::new(width, height, &b)) {
        (Ok(a), Ok(b)) => metrics::psnr(a, b).unwrap_or(f64::NAN),
        _ => f64::NAN,
    }
}
