//! The settings text of `gCRM` (spec §7.1.1): how a file was made, as typed fields written
//! as `key=value` lines. Each key and value is spelled here, not by Rust's `Debug` of the
//! encoder's own types, so that renaming an item of the encoder never changes a file; and
//! the spelling is the one the encoder has always written, so that no file changes either.
//!
//! Reading is lenient: the text is ancillary, older and other encoders wrote what they
//! liked, and a file is never refused for it (beyond UTF-8, §7.1). Lines that are not a
//! known key with a value of its grammar are kept, in order, in [`EncoderSettings::other`];
//! empty lines are skipped.

use std::fmt::Write as _;

/// How the encoder started the Gaussians (`init=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InitKind {
    /// `Adaptive`: placed on the image's content.
    Adaptive,
    /// `Random`: the paper's random cold start.
    Random,
}

/// What the encoder spent (`budget=`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BudgetKind {
    /// `Gaussians(N)`.
    Gaussians(u64),
    /// `Bpp(X)`: bits per pixel of the whole file.
    Bpp(f32),
    /// `TargetPsnr(X)`: dB of the stored file.
    TargetPsnr(f32),
}

/// The loss the encoder minimized (`loss=`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LossKind {
    /// `L2`.
    L2,
    /// `L1MsSsim { lambda: X }`: the paper's Eq. 9.
    L1MsSsim { lambda: f32 },
}

/// The settings of one encode. Every field is optional on reading; the encoder writes the
/// first seven always and the last four only where they differ from its defaults.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EncoderSettings {
    /// `encoder=`: name and version, e.g. `gsi 0.1.0`.
    pub encoder: Option<String>,
    pub init: Option<InitKind>,
    /// `iterations=`: optimizer steps of the first pass.
    pub iterations: Option<u32>,
    pub seed: Option<u64>,
    pub budget: Option<BudgetKind>,
    pub loss: Option<LossKind>,
    /// `bits=P/C/K/O/A`: position, covariance, colour, opacity and angle depths (for
    /// shaped angles, spec §5.4.5, the uniform depth whose noise they match).
    pub bits: Option<[u8; 5]>,
    /// `coarse=F/X`: the first fraction `X` of the steps fitted `F` times smaller.
    pub coarse: Option<(u32, f32)>,
    /// `color_solve=N`: conjugate-gradient iterations of each colour solve.
    pub color_solve: Option<u32>,
    /// `solve_stored_colors=false`: the stored colours were not solved again.
    pub solve_stored_colors: Option<bool>,
    /// `dark_gain=X`: a dark image was fitted brightened by `X` (§7.1.1).
    pub dark_gain: Option<f32>,
    /// Lines that are not a known key with a value of its grammar, in order.
    pub other: Vec<String>,
}

/// The shortest decimal that reads back as `x`, with `.0` where it would have no
/// fraction or exponent: the `Bpp(…)`, `TargetPsnr(…)` and `lambda` spelling.
fn decimal_point(x: f32) -> String {
    format!("{x:?}")
}

impl EncoderSettings {
    /// The `key=value` lines, in the order of the fields, joined by `\n` (no final one).
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let mut line = |k: &str, v: String| {
            if !s.is_empty() {
                s.push('\n');
            }
            let _ = write!(s, "{k}={v}");
        };
        if let Some(e) = &self.encoder {
            line("encoder", e.clone());
        }
        if let Some(i) = self.init {
            line(
                "init",
                match i {
                    InitKind::Adaptive => "Adaptive".into(),
                    InitKind::Random => "Random".into(),
                },
            );
        }
        if let Some(n) = self.iterations {
            line("iterations", n.to_string());
        }
        if let Some(n) = self.seed {
            line("seed", n.to_string());
        }
        if let Some(b) = self.budget {
            line(
                "budget",
                match b {
                    BudgetKind::Gaussians(n) => format!("Gaussians({n})"),
                    BudgetKind::Bpp(x) => format!("Bpp({})", decimal_point(x)),
                    BudgetKind::TargetPsnr(x) => format!("TargetPsnr({})", decimal_point(x)),
                },
            );
        }
        if let Some(l) = self.loss {
            line(
                "loss",
                match l {
                    LossKind::L2 => "L2".into(),
                    LossKind::L1MsSsim { lambda } => {
                        format!("L1MsSsim {{ lambda: {} }}", decimal_point(lambda))
                    }
                },
            );
        }
        if let Some([p, c, k, o, a]) = self.bits {
            line("bits", format!("{p}/{c}/{k}/{o}/{a}"));
        }
        if let Some((f, x)) = self.coarse {
            line("coarse", format!("{f}/{x}"));
        }
        if let Some(n) = self.color_solve {
            line("color_solve", n.to_string());
        }
        if let Some(b) = self.solve_stored_colors {
            line("solve_stored_colors", b.to_string());
        }
        if let Some(g) = self.dark_gain {
            line("dark_gain", g.to_string());
        }
        for o in &self.other {
            if !s.is_empty() {
                s.push('\n');
            }
            s.push_str(o);
        }
        s
    }

    /// The settings a text records; never fails (see the module's documentation).
    pub fn parse(text: &str) -> EncoderSettings {
        let mut s = EncoderSettings::default();
        // Empty lines carry nothing (and could not be told from the end of the text).
        for raw in text.lines().filter(|l| !l.is_empty()) {
            if !s.take(raw) {
                s.other.push(raw.to_owned());
            }
        }
        s
    }

    /// Read one line into its field; false where it is not a known key with a value of
    /// its grammar, or its field is already set.
    fn take(&mut self, line: &str) -> bool {
        let Some((key, v)) = line.split_once('=') else {
            return false;
        };
        let num = |x: &str| x.parse::<f32>().ok().filter(|x| x.is_finite());
        let inside = |v: &str, name: &str| {
            v.strip_prefix(name)?
                .strip_prefix('(')?
                .strip_suffix(')')
                .map(str::to_owned)
        };
        fn set<T>(slot: &mut Option<T>, v: Option<T>) -> bool {
            match (slot.is_none(), v) {
                (true, Some(v)) => {
                    *slot = Some(v);
                    true
                }
                _ => false,
            }
        }
        match key {
            "encoder" => set(&mut self.encoder, Some(v.to_owned())),
            "init" => set(
                &mut self.init,
                match v {
                    "Adaptive" => Some(InitKind::Adaptive),
                    "Random" => Some(InitKind::Random),
                    _ => None,
                },
            ),
            "iterations" => set(&mut self.iterations, v.parse().ok()),
            "seed" => set(&mut self.seed, v.parse().ok()),
            "budget" => set(
                &mut self.budget,
                if let Some(n) = inside(v, "Gaussians") {
                    n.parse().ok().map(BudgetKind::Gaussians)
                } else if let Some(x) = inside(v, "Bpp") {
                    num(&x).map(BudgetKind::Bpp)
                } else if let Some(x) = inside(v, "TargetPsnr") {
                    num(&x).map(BudgetKind::TargetPsnr)
                } else {
                    None
                },
            ),
            "loss" => set(
                &mut self.loss,
                match v {
                    "L2" => Some(LossKind::L2),
                    _ => v
                        .strip_prefix("L1MsSsim { lambda: ")
                        .and_then(|x| x.strip_suffix(" }"))
                        .and_then(num)
                        .map(|lambda| LossKind::L1MsSsim { lambda }),
                },
            ),
            "bits" => {
                let d: Vec<u8> = v.split('/').filter_map(|x| x.parse().ok()).collect();
                let ok = d.len() == 5 && v.split('/').count() == 5;
                set(&mut self.bits, ok.then(|| [d[0], d[1], d[2], d[3], d[4]]))
            }
            "coarse" => set(
                &mut self.coarse,
                v.split_once('/')
                    .and_then(|(f, x)| Some((f.parse().ok()?, num(x)?))),
            ),
            "color_solve" => set(&mut self.color_solve, v.parse().ok()),
            "solve_stored_colors" => set(&mut self.solve_stored_colors, v.parse().ok()),
            "dark_gain" => set(&mut self.dark_gain, num(v)),
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the encoder has always written reads back into every field and is written
    /// again byte for byte, in both directions.
    #[test]
    fn the_encoders_text_round_trips() {
        for text in [
            "encoder=gsi 0.1.0\ninit=Adaptive\niterations=600\nseed=0\nbudget=Bpp(1.0)\nloss=L2\nbits=12/6/8/6/7\ncoarse=2/0.5\ndark_gain=6.25",
            "encoder=gsi 0.1.0\ninit=Random\niterations=80\nseed=7\nbudget=Gaussians(400)\nloss=L1MsSsim { lambda: 0.2 }\nbits=12/8/8/6/7\ncolor_solve=5\nsolve_stored_colors=false",
            "encoder=gsi 0.1.0\ninit=Adaptive\niterations=600\nseed=0\nbudget=TargetPsnr(35.5)\nloss=L2\nbits=13/6/8/6/7",
        ] {
            let s = EncoderSettings::parse(text);
            assert!(s.other.is_empty(), "{text}: {:?}", s.other);
            assert_eq!(s.to_text(), text);
        }
    }

    /// Another encoder's lines, or broken ones, are kept as they are (empty ones skipped);
    /// nothing fails.
    #[test]
    fn unknown_and_broken_lines_are_kept() {
        let text = "encoder=other 2\nbudget=Bpp(x)\nquality=9\n\nno equals sign\nbits=1/2/3\ninit=Adaptive\ninit=Random";
        let s = EncoderSettings::parse(text);
        assert_eq!(s.encoder.as_deref(), Some("other 2"));
        assert_eq!(s.init, Some(InitKind::Adaptive));
        assert_eq!(s.budget, None);
        assert_eq!(
            s.other,
            [
                "budget=Bpp(x)",
                "quality=9",
                "no equals sign",
                "bits=1/2/3",
                "init=Random"
            ]
        );
        // Written again, it reads back into the same fields.
        assert_eq!(EncoderSettings::parse(&s.to_text()), s);
    }
}
