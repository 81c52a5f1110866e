//! The stage-2 ancillary chunks (spec §7.2): `gENH`, a fitted colour enhancer, and
//! `gORC`, the colour records it replaced.
//!
//! Only bytes live here. What the numbers mean (how a weight map and the operators turn
//! one colour into another) is `gsi_enhance::enhance::Enhancer`; keeping the two apart lets a
//! decoder built without the enhancer still parse, validate and report these chunks.

use super::error::{invalid, Error, ErrorKind, Result};
use super::limits::{AllocBudget, Limits};
use super::records::Attribute;
use byteorder::{BigEndian, ByteOrder, WriteBytesExt};

/// `gENH` layout of an enhancer without denoising: the only layout before it had one.
pub const ENHANCER_VERSION: u8 = 1;
/// `gENH` layout of an enhancer that denoises first: layout 1 with a [`Denoise`] record
/// between the fixed part and the blocks. Written only where there is one, so that an
/// enhancer without it stays readable by every decoder of layout 1.
pub const ENHANCER_VERSION_DENOISED: u8 = 2;
/// `gENH` layout of an enhancer with a tone curve after the mixture: byte 3 says which of
/// the [`Denoise`] and [`Tone`] records follow the fixed part (bit 0 and bit 1; bit 1 is
/// always set, since without a tone record layouts 1 and 2 serve).
pub const ENHANCER_VERSION_TONED: u8 = 3;
/// `gENH` layout of an enhancer with a gain map after the mixture (spec §7.2.3): byte 3
/// as in layout 3 plus bit 2 (always set), a 4-byte [`GainMap`] record after the others
/// and an eighth block, the gains.
pub const ENHANCER_VERSION_GAINED: u8 = 4;
/// `gENH` layout of an enhancer with a chroma map after the mixture and any gain map
/// (spec §7.2.4): byte 3 as in layout 4 plus bit 3 (always set; bit 2 may be clear), a
/// 4-byte [`ChromaMap`] record after the others and a block of scales after the others.
pub const ENHANCER_VERSION_CHROMA: u8 = 5;
/// `gENH` layout of an enhancer that first removes the Gaussians fitted to noise (spec
/// §7.2.5): byte 3 as in layout 5 plus bit 4 (always set; bits 0 to 3 may be clear), a
/// 4-byte [`Speckle`] record after the others and no block.
pub const ENHANCER_VERSION_SPECKLE: u8 = 6;
/// Byte 3 of layouts 3 to 6: a denoise record follows.
pub const RECORD_DENOISE: u8 = 1;
/// Byte 3 of layouts 3 to 6: a tone record follows (after the denoise record, if any).
pub const RECORD_TONE: u8 = 2;
/// Byte 3 of layouts 4 to 6: a gain record follows the others, and block 7 holds the gains.
pub const RECORD_GAIN: u8 = 4;
/// Byte 3 of layouts 5 and 6: a chroma record follows the others, and the last block
/// holds the scales.
pub const RECORD_CHROMA: u8 = 8;
/// Byte 3 of layout 6: a speckle record follows the others.
pub const RECORD_SPECKLE: u8 = 16;
/// Bytes of the speckle record of layout 6.
pub const SPECKLE_LEN: usize = 4;
/// Bytes of the chroma record of layout 5.
pub const CHROMA_LEN: usize = 4;
/// Bytes of the gain record of layout 4.
pub const GAIN_LEN: usize = 4;
/// Largest gain a gain map may hold (spec §7.2.3).
pub const MAX_GAIN: f32 = 64.0;
/// Bytes of the tone record of layout 3.
pub const TONE_LEN: usize = 12;
/// Most tone passes a `gENH` may ask for.
pub const MAX_TONE_PASSES: u8 = 8;
/// Largest tone exponent a `gENH` may hold.
pub const MAX_TONE_EXPONENT: f32 = 4.0;
/// Fixed part of a `gENH` payload of layout 1; seven length-prefixed attribute blocks
/// follow (after the [`DENOISE_LEN`]-byte denoise record in layout 2, and after the
/// records byte 3 names in layout 3).
pub const ENHANCER_FIXED_LEN: usize = 68;
/// Bytes of the denoise record of layout 2.
pub const DENOISE_LEN: usize = 12;
/// Most denoising passes a `gENH` may ask for.
pub const MAX_DENOISE_PASSES: u8 = 8;
/// Shortest `gENH` payload: the fixed part and seven empty one-component blocks.
pub const MIN_ENHANCER_LEN: usize =
    ENHANCER_FIXED_LEN + 7 * (4 + super::records::attribute_preamble_len(1));
/// Most operators (identity included) a `gENH` may declare.
pub const MAX_EXPERTS: u8 = 64;
/// Widest hidden layer a `gENH` may declare.
pub const MAX_HIDDEN: u8 = 64;
/// Largest weight-map side, in cells.
pub const MAX_MAP_SIDE: u16 = 1024;
/// Number of parameter tensors per operator: `W1, b1, W2, b2, W3, b3`.
pub const TENSORS: usize = 6;

/// Zero-shot loss settings the enhancer was fitted with, kept so a file says how it was made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitSettings {
    /// λ1..λ7 of the paper's Eq. 16 and 22.
    pub weights: [f32; 7],
    /// Exposure target E of Eq. 17.
    pub exposure: f32,
    /// Saturation threshold τ of Eq. 18.
    pub saturation_tau: f32,
    /// Contrast factor γ of Eq. 20.
    pub contrast_gamma: f32,
    pub iterations: u32,
    pub seed: u64,
}

/// The smoothing across neighbouring Gaussians that runs before the mixture (spec
/// §7.2.1): how far apart two colours may be and still be averaged, how far each step
/// goes, and how many steps. What the numbers do is `gsi_enhance::enhance::denoise`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Denoise {
    /// Range `r`: neighbours whose values differ by about `r` or more are barely mixed.
    pub range: f32,
    /// Strength `s` in `(0, 1]`: the share of each step taken.
    pub strength: f32,
    /// Passes, `1..=MAX_DENOISE_PASSES`.
    pub passes: u8,
}

/// The tone curve that runs after the mixture (spec §7.2.2): `a·x^g` per channel, on the
/// values the render shows at the Gaussians' centres, reached in `passes` steps. What the
/// numbers do is `gsi_enhance::enhance::tone`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tone {
    /// Exponent `g` in `(0, MAX_TONE_EXPONENT]`: below 1 lifts shadows more than
    /// highlights.
    pub exponent: f32,
    /// Scale `a` in `(0, 64]`.
    pub scale: f32,
    /// Passes, `1..=MAX_TONE_PASSES`.
    pub passes: u8,
}

/// The gain map that runs after the mixture (spec §7.2.3): `width × height` positive gains
/// over the image, bilinearly interpolated at each Gaussian's centre. What the numbers do
/// is `gsi_enhance::enhance::gain`.
#[derive(Clone, Debug, PartialEq)]
pub struct GainMap {
    pub width: u16,
    pub height: u16,
    /// The gains, row by row, one component each, every one in `(0, MAX_GAIN]`.
    pub gains: Attribute,
}

/// The chroma map that runs after the mixture and any gain map (spec §7.2.4):
/// `width × height` scales in `[0, 1]` over the image, bilinearly interpolated at each
/// Gaussian's centre, by which the colour's distance from its own grey is multiplied.
/// What the numbers do is `gsi_enhance::enhance::chroma`.
#[derive(Clone, Debug, PartialEq)]
pub struct ChromaMap {
    pub width: u16,
    pub height: u16,
    /// The scales, row by row, one component each, every one in `[0, 1]`.
    pub scales: Attribute,
}

/// The removal of the Gaussians fitted to noise that runs before everything else (spec
/// §7.2.5): each `sum` colour shrunk by the non-negative garrote `1 − t² / (e·F)` of its
/// mean square `e` and its footprint's energy `F`, and removed where that is not
/// positive. What the numbers do is `gsi_enhance::enhance::speckle`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Speckle {
    /// `t` in `(0, 1]`, in colour units: the noise level times how many of them a
    /// Gaussian's amplitude must stand above it.
    pub threshold: f32,
}

/// A `gENH` chunk: the mixture of colour operators and the weight map that mixes them.
///
/// Every learned number is stored quantized (as an [`Attribute`] of one component, the
/// same layout as spec §5.1), and the enhancer that rewrote the colours is the
/// *dequantized* one, so applying a stored enhancer reproduces the stored colours
/// exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct EnhancerRecord {
    /// K: operators including the identity (operator 0).
    pub experts: u8,
    /// Width of both hidden layers of every operator.
    pub hidden: u8,
    /// Each operator's output is clamped to `[clamp[0], clamp[1]]`.
    pub clamp: [f32; 2],
    pub map_width: u16,
    pub map_height: u16,
    /// Mixing logits, `map_height × map_width` cells of K values (K innermost).
    pub map: Attribute,
    /// `W1 (hidden×3), b1 (hidden), W2 (hidden×hidden), b2 (hidden), W3 (1×hidden), b3 (1)`
    /// of operators 1..K, operator-major within each tensor, row-major matrices.
    pub tensors: [Attribute; TENSORS],
    pub fit: FitSettings,
    /// Smoothing applied to the colours before the mixture (layouts 2 and 3), if any.
    pub denoise: Option<Denoise>,
    /// Tone curve applied after the mixture (layouts 3 and 4), if any.
    pub tone: Option<Tone>,
    /// Gain map applied after the mixture, before any tone curve (layouts 4 and 5), if any.
    pub gain: Option<GainMap>,
    /// Chroma map applied after the gain map, before any tone curve (layouts 5 and 6),
    /// if any.
    pub chroma: Option<ChromaMap>,
    /// Removal of the Gaussians fitted to noise, before everything else (layout 6), if
    /// any.
    pub speckle: Option<Speckle>,
}

/// Number of values in each of the six tensors of one operator.
pub fn tensor_sizes(hidden: usize) -> [usize; TENSORS] {
    [hidden * 3, hidden, hidden * hidden, hidden, hidden, 1]
}

impl EnhancerRecord {
    /// Values each attribute block must hold: the map, then the six tensors.
    fn counts(&self) -> [u64; 7] {
        counts(self.experts, self.hidden, self.map_width, self.map_height)
    }

    /// The payload of a `gENH` chunk.
    pub fn to_payload(&self, zstd_level: i32) -> Result<Vec<u8>> {
        self.validate()?;
        let bit = |present: bool, b: u8| if present { b } else { 0 };
        let records = bit(self.denoise.is_some(), RECORD_DENOISE)
            | bit(self.tone.is_some(), RECORD_TONE)
            | bit(self.gain.is_some(), RECORD_GAIN)
            | bit(self.chroma.is_some(), RECORD_CHROMA)
            | bit(self.speckle.is_some(), RECORD_SPECKLE);
        // The lowest layout that holds what is stored (spec §7.2).
        let (version, records) = match records {
            0 => (ENHANCER_VERSION, 0),
            RECORD_DENOISE => (ENHANCER_VERSION_DENOISED, 0),
            r if r & RECORD_SPECKLE != 0 => (ENHANCER_VERSION_SPECKLE, r),
            r if r & RECORD_CHROMA != 0 => (ENHANCER_VERSION_CHROMA, r),
            r if r & RECORD_GAIN == 0 => (ENHANCER_VERSION_TONED, r),
            r => (ENHANCER_VERSION_GAINED, r),
        };
        let mut out = vec![version, self.experts, self.hidden, records];
        out.write_f32::<BigEndian>(self.clamp[0])?;
        out.write_f32::<BigEndian>(self.clamp[1])?;
        out.write_u16::<BigEndian>(self.map_width)?;
        out.write_u16::<BigEndian>(self.map_height)?;
        out.write_u32::<BigEndian>(self.fit.iterations)?;
        out.write_u64::<BigEndian>(self.fit.seed)?;
        let f = &self.fit;
        for x in f
            .weights
            .iter()
            .chain([&f.exposure, &f.saturation_tau, &f.contrast_gamma])
        {
            out.write_f32::<BigEndian>(*x)?;
        }
        debug_assert_eq!(out.len(), ENHANCER_FIXED_LEN);
        if let Some(d) = &self.denoise {
            write_record(&mut out, d.range, d.strength, d.passes);
        }
        if let Some(t) = &self.tone {
            write_record(&mut out, t.exponent, t.scale, t.passes);
        }
        if let Some(g) = &self.gain {
            out.write_u16::<BigEndian>(g.width)?;
            out.write_u16::<BigEndian>(g.height)?;
        }
        if let Some(c) = &self.chroma {
            out.write_u16::<BigEndian>(c.width)?;
            out.write_u16::<BigEndian>(c.height)?;
        }
        if let Some(k) = &self.speckle {
            out.write_f32::<BigEndian>(k.threshold)?;
        }
        let gains = self.gain.as_ref().map(|g| &g.gains);
        let scales = self.chroma.as_ref().map(|c| &c.scales);
        for a in std::iter::once(&self.map)
            .chain(&self.tensors)
            .chain(gains)
            .chain(scales)
        {
            let p = a.to_payload(zstd_level)?;
            out.write_u32::<BigEndian>(p.len() as u32)?;
            out.extend_from_slice(&p);
        }
        Ok(out)
    }

    /// The checks [`parse`](Self::parse) makes, for records built in memory.
    fn validate(&self) -> Result<()> {
        check_shape(self.experts, self.hidden, self.map_width, self.map_height)?;
        check_clamp(self.clamp)?;
        check_fit(&self.fit)?;
        if let Some(d) = &self.denoise {
            check_denoise(d)?;
        }
        if let Some(t) = &self.tone {
            check_tone(t)?;
        }
        if let Some(g) = &self.gain {
            check_gain(g)?;
        }
        if let Some(c) = &self.chroma {
            check_chroma(c)?;
        }
        if let Some(k) = &self.speckle {
            check_speckle(k)?;
        }
        for (a, n) in std::iter::once(&self.map)
            .chain(&self.tensors)
            .zip(self.counts())
        {
            if a.components() != 1 || a.count() as u64 != n {
                return Err(invalid(format!(
                    "enhancer block of {} values, expected {n}",
                    a.count()
                )));
            }
        }
        Ok(())
    }

    /// Parse a `gENH` payload, bounding every allocation by `limits`.
    pub fn parse(p: &[u8], limits: &Limits) -> Result<EnhancerRecord> {
        if p.len() < ENHANCER_FIXED_LEN {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!(
                    "{} bytes, shorter than the {ENHANCER_FIXED_LEN}-byte gENH preamble",
                    p.len()
                ),
            ));
        }
        // Which records follow the fixed part (byte 3's bits, spec §7.2).
        let records = match (p[0], p[3]) {
            (ENHANCER_VERSION, 0) => 0,
            (ENHANCER_VERSION_DENOISED, 0) => RECORD_DENOISE,
            (ENHANCER_VERSION_TONED, r)
                if r & !(RECORD_DENOISE | RECORD_TONE) == 0 && r & RECORD_TONE != 0 =>
            {
                r
            }
            (ENHANCER_VERSION_GAINED, r)
                if r & !(RECORD_DENOISE | RECORD_TONE | RECORD_GAIN) == 0
                    && r & RECORD_GAIN != 0 =>
            {
                r
            }
            (ENHANCER_VERSION_CHROMA, r)
                if r & !(RECORD_DENOISE | RECORD_TONE | RECORD_GAIN | RECORD_CHROMA) == 0
                    && r & RECORD_CHROMA != 0 =>
            {
                r
            }
            (ENHANCER_VERSION_SPECKLE, r) if r & !0x1f == 0 && r & RECORD_SPECKLE != 0 => r,
            (
                ENHANCER_VERSION
                | ENHANCER_VERSION_DENOISED
                | ENHANCER_VERSION_TONED
                | ENHANCER_VERSION_GAINED
                | ENHANCER_VERSION_CHROMA
                | ENHANCER_VERSION_SPECKLE,
                r,
            ) => return Err(invalid(format!("gENH layout {}: byte 3 is {r:#04x}", p[0]))),
            (v, _) => {
                return Err(Error::new(
                    ErrorKind::UnsupportedVersion,
                    format!(
                        "gENH layout {v}, this decoder reads {ENHANCER_VERSION} to \
                         {ENHANCER_VERSION_SPECKLE}"
                    ),
                ))
            }
        };
        let (has_denoise, has_tone, has_gain, has_chroma, has_speckle) = (
            records & RECORD_DENOISE != 0,
            records & RECORD_TONE != 0,
            records & RECORD_GAIN != 0,
            records & RECORD_CHROMA != 0,
            records & RECORD_SPECKLE != 0,
        );
        let denoise_at = ENHANCER_FIXED_LEN;
        let tone_at = denoise_at + if has_denoise { DENOISE_LEN } else { 0 };
        let gain_at = tone_at + if has_tone { TONE_LEN } else { 0 };
        let chroma_at = gain_at + if has_gain { GAIN_LEN } else { 0 };
        let speckle_at = chroma_at + if has_chroma { CHROMA_LEN } else { 0 };
        let blocks_at = speckle_at + if has_speckle { SPECKLE_LEN } else { 0 };
        if p.len() < blocks_at {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!(
                    "{} bytes, shorter than the {blocks_at}-byte preamble of gENH layout {}",
                    p.len(),
                    p[0]
                ),
            ));
        }
        let (experts, hidden) = (p[1], p[2]);
        let f32_at = |o: usize| BigEndian::read_f32(&p[o..o + 4]);
        let clamp = [f32_at(4), f32_at(8)];
        let map_width = BigEndian::read_u16(&p[12..14]);
        let map_height = BigEndian::read_u16(&p[14..16]);
        let fit = FitSettings {
            iterations: BigEndian::read_u32(&p[16..20]),
            seed: BigEndian::read_u64(&p[20..28]),
            weights: std::array::from_fn(|i| f32_at(28 + 4 * i)),
            exposure: f32_at(56),
            saturation_tau: f32_at(60),
            contrast_gamma: f32_at(64),
        };
        check_shape(experts, hidden, map_width, map_height)?;
        check_clamp(clamp)?;
        check_fit(&fit)?;
        let denoise = if has_denoise {
            let (range, strength, passes) = read_record(&p[denoise_at..tone_at], "denoise")?;
            let d = Denoise {
                range,
                strength,
                passes,
            };
            check_denoise(&d)?;
            Some(d)
        } else {
            None
        };
        let tone = if has_tone {
            let (exponent, scale, passes) = read_record(&p[tone_at..gain_at], "tone")?;
            let t = Tone {
                exponent,
                scale,
                passes,
            };
            check_tone(&t)?;
            Some(t)
        } else {
            None
        };
        let speckle = if has_speckle {
            let k = Speckle {
                threshold: f32_at(speckle_at),
            };
            check_speckle(&k)?;
            Some(k)
        } else {
            None
        };

        let shape_at = |at: usize| {
            (
                BigEndian::read_u16(&p[at..at + 2]),
                BigEndian::read_u16(&p[at + 2..at + 4]),
            )
        };
        let gain_shape = has_gain.then(|| shape_at(gain_at));
        if let Some((w, h)) = gain_shape {
            check_map_shape(w, h, "gain")?;
        }
        let chroma_shape = has_chroma.then(|| shape_at(chroma_at));
        if let Some((w, h)) = chroma_shape {
            check_map_shape(w, h, "chroma")?;
        }
        let cells = |(w, h): (u16, u16)| u64::from(w) * u64::from(h);
        let gain_count = gain_shape.map(cells);
        let chroma_count = chroma_shape.map(cells);

        let mut budget = AllocBudget::new(limits);
        let mut rest = &p[blocks_at..];
        let mut blocks = Vec::with_capacity(9);
        let all = counts(experts, hidden, map_width, map_height)
            .into_iter()
            .chain(gain_count)
            .chain(chroma_count);
        for (b, n) in all.enumerate() {
            if rest.len() < 4 {
                return Err(Error::new(
                    ErrorKind::BadChunkLength,
                    format!("gENH ends before block {b}"),
                ));
            }
            let len = BigEndian::read_u32(&rest[..4]) as usize;
            rest = &rest[4..];
            if len > rest.len() {
                return Err(Error::new(
                    ErrorKind::BadChunkLength,
                    format!("gENH block {b} of {len} bytes, {} left", rest.len()),
                ));
            }
            // `counts` stays far below u32::MAX by the shape limits.
            blocks.push(Attribute::parse(
                &rest[..len],
                1,
                n as u32,
                limits,
                &mut budget,
                None,
            )?);
            rest = &rest[len..];
        }
        if !rest.is_empty() {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!("{} bytes after the last gENH block", rest.len()),
            ));
        }
        let mut blocks = blocks.into_iter();
        let map = blocks.next().expect("seven blocks");
        let tensors = std::array::from_fn(|_| blocks.next().expect("seven blocks"));
        // One block per map the records byte names, in the order of the records.
        let gain = match gain_shape {
            Some((width, height)) => {
                let g = GainMap {
                    width,
                    height,
                    gains: blocks.next().expect("a block per count"),
                };
                check_gain(&g)?;
                Some(g)
            }
            None => None,
        };
        let chroma = match chroma_shape {
            Some((width, height)) => {
                let c = ChromaMap {
                    width,
                    height,
                    scales: blocks.next().expect("a block per count"),
                };
                check_chroma(&c)?;
                Some(c)
            }
            None => None,
        };
        Ok(EnhancerRecord {
            experts,
            hidden,
            clamp,
            map_width,
            map_height,
            map,
            tensors,
            fit,
            denoise,
            tone,
            gain,
            chroma,
            speckle,
        })
    }
}

/// The shape the denoise and tone records share (spec §7.2): two f32, a pass count and
/// three reserved zero bytes, 12 in all ([`DENOISE_LEN`], [`TONE_LEN`]).
fn write_record(out: &mut Vec<u8>, a: f32, b: f32, passes: u8) {
    out.extend_from_slice(&a.to_be_bytes());
    out.extend_from_slice(&b.to_be_bytes());
    out.extend_from_slice(&[passes, 0, 0, 0]);
}

/// [`write_record`]'s fields from a 12-byte record, its reserved bytes checked; `what`
/// names it in the error.
fn read_record(r: &[u8], what: &str) -> Result<(f32, f32, u8)> {
    if r[9..12] != [0, 0, 0] {
        return Err(invalid(format!("gENH {what} record: reserved bytes not 0")));
    }
    Ok((
        BigEndian::read_f32(&r[0..4]),
        BigEndian::read_f32(&r[4..8]),
        r[8],
    ))
}

fn counts(experts: u8, hidden: u8, map_width: u16, map_height: u16) -> [u64; 7] {
    let k = u64::from(experts);
    let ops = k.saturating_sub(1);
    let t = tensor_sizes(usize::from(hidden));
    let cells = u64::from(map_width) * u64::from(map_height);
    let mut out = [cells * k; 7];
    for (o, n) in out[1..].iter_mut().zip(t) {
        *o = ops * n as u64;
    }
    out
}

fn check_shape(experts: u8, hidden: u8, map_width: u16, map_height: u16) -> Result<()> {
    if !(1..=MAX_EXPERTS).contains(&experts) {
        return Err(invalid(format!(
            "{experts} operators, allowed 1..={MAX_EXPERTS}"
        )));
    }
    if !(1..=MAX_HIDDEN).contains(&hidden) {
        return Err(invalid(format!(
            "hidden width {hidden}, allowed 1..={MAX_HIDDEN}"
        )));
    }
    for side in [map_width, map_height] {
        if !(1..=MAX_MAP_SIDE).contains(&side) {
            return Err(invalid(format!(
                "weight map side {side}, allowed 1..={MAX_MAP_SIDE}"
            )));
        }
    }
    Ok(())
}

fn check_clamp([lo, hi]: [f32; 2]) -> Result<()> {
    let max = crate::contract::COLOR_MAX;
    if !(lo.is_finite() && hi.is_finite() && -max <= lo && lo < hi && hi <= max) {
        return Err(invalid(format!("operator clamp [{lo}, {hi}]")));
    }
    Ok(())
}

fn check_fit(f: &FitSettings) -> Result<()> {
    let all = f
        .weights
        .iter()
        .chain([&f.exposure, &f.saturation_tau, &f.contrast_gamma]);
    if all.clone().any(|x| !x.is_finite()) {
        return Err(invalid("non-finite enhancer loss setting"));
    }
    Ok(())
}

/// Spec §7.2.1: a range in `(0, 64]`, a strength in `(0, 1]`, `1..=8` passes.
fn check_denoise(d: &Denoise) -> Result<()> {
    let range_ok = d.range > 0.0 && d.range <= crate::contract::COLOR_MAX;
    let strength_ok = d.strength > 0.0 && d.strength <= 1.0;
    if !(range_ok && strength_ok && (1..=MAX_DENOISE_PASSES).contains(&d.passes)) {
        return Err(invalid(format!(
            "gENH denoise: range {}, strength {}, {} passes",
            d.range, d.strength, d.passes
        )));
    }
    Ok(())
}

/// Spec §7.2.5: a threshold in `(0, 1]` (NaN refused).
fn check_speckle(k: &Speckle) -> Result<()> {
    if !(k.threshold > 0.0 && k.threshold <= 1.0) {
        return Err(invalid(format!(
            "gENH speckle: threshold {}, allowed (0, 1]",
            k.threshold
        )));
    }
    Ok(())
}

/// Spec §7.2.2: an exponent in `(0, 4]`, a scale in `(0, 64]`, `1..=8` passes.
fn check_tone(t: &Tone) -> Result<()> {
    let exponent_ok = t.exponent > 0.0 && t.exponent <= MAX_TONE_EXPONENT;
    let scale_ok = t.scale > 0.0 && t.scale <= crate::contract::COLOR_MAX;
    if !(exponent_ok && scale_ok && (1..=MAX_TONE_PASSES).contains(&t.passes)) {
        return Err(invalid(format!(
            "gENH tone: exponent {}, scale {}, {} passes",
            t.exponent, t.scale, t.passes
        )));
    }
    Ok(())
}

/// Spec §7.2.3 and §7.2.4: a map's sides in `1..=1024`; `what` names the map.
fn check_map_shape(width: u16, height: u16, what: &str) -> Result<()> {
    for side in [width, height] {
        if !(1..=MAX_MAP_SIDE).contains(&side) {
            return Err(invalid(format!(
                "{what} map side {side}, allowed 1..={MAX_MAP_SIDE}"
            )));
        }
    }
    Ok(())
}

/// A map's block: one component, `width·height` values; `what` names the map.
fn check_map_block(a: &Attribute, width: u16, height: u16, what: &str) -> Result<()> {
    check_map_shape(width, height, what)?;
    let n = usize::from(width) * usize::from(height);
    if a.components() != 1 || a.count() != n {
        return Err(invalid(format!(
            "{what} map block of {} values, expected {n}",
            a.count()
        )));
    }
    Ok(())
}

/// Spec §7.2.4: sides in `1..=1024`, `width·height` scales, each in `[0, 1]`, checked by
/// the block's quantizer's ends as for the gains.
fn check_chroma(c: &ChromaMap) -> Result<()> {
    check_map_block(&c.scales, c.width, c.height, "chroma")?;
    let q = &c.scales.quantizers[0];
    if !(q.min >= 0.0 && q.max <= 1.0 && q.min <= q.max) {
        return Err(invalid(format!(
            "chroma map range [{}, {}], allowed [0, 1]",
            q.min, q.max
        )));
    }
    Ok(())
}

/// Spec §7.2.3: sides in `1..=1024`, `width·height` gains, each in `(0, 64]`. The gains
/// of a block lie between its quantizer's ends, so checking the ends checks them all.
fn check_gain(g: &GainMap) -> Result<()> {
    check_map_block(&g.gains, g.width, g.height, "gain")?;
    let q = &g.gains.quantizers[0];
    if !(q.min > 0.0 && q.max <= MAX_GAIN && q.min <= q.max) {
        return Err(invalid(format!(
            "gain map range [{}, {}], allowed (0, {MAX_GAIN}]",
            q.min, q.max
        )));
    }
    Ok(())
}

/// A `gORC` chunk: what stage 2 replaced, so that `--revert` restores the file exactly.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OriginalColors {
    /// The `GCOL` payload before enhancement, byte for byte.
    pub colors: Vec<u8>,
    /// The `gCRM` payload before enhancement, when the file had one.
    pub metadata: Option<Vec<u8>>,
}

const ORC_HAS_META: u8 = 1;

impl OriginalColors {
    pub fn to_payload(&self) -> Result<Vec<u8>> {
        let mut out = Vec::with_capacity(5 + self.colors.len());
        out.push(if self.metadata.is_some() {
            ORC_HAS_META
        } else {
            0
        });
        let len = u32::try_from(self.colors.len()).map_err(|_| invalid("GCOL payload too long"))?;
        out.write_u32::<BigEndian>(len)?;
        out.extend_from_slice(&self.colors);
        if let Some(m) = &self.metadata {
            out.extend_from_slice(m);
        }
        Ok(out)
    }

    /// The checks of spec §7.3 beyond the framing [`parse`](Self::parse) checks: the
    /// colours are a `GCOL` payload for the file of `records` (its count, and its
    /// covariance where they are stored by footprint), and the metadata, where there is
    /// some, a valid `gCRM` payload.
    pub fn validate(&self, records: &super::records::Records) -> Result<()> {
        let sizes = records.footprint_sizes();
        Attribute::parse_standalone(
            &self.colors,
            3,
            records.header.count,
            &Limits::default(),
            sizes.as_deref(),
        )?;
        if let Some(m) = &self.metadata {
            super::meta::CompressionMeta::parse(m)?;
        }
        Ok(())
    }

    /// Split a `gORC` payload. The parts are only framed here: they are parsed as `GCOL`
    /// and `gCRM` payloads where they are used ([`validate`](Self::validate)).
    pub fn parse(p: &[u8]) -> Result<OriginalColors> {
        if p.len() < 5 {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!("gORC of {} bytes", p.len()),
            ));
        }
        let flags = p[0];
        if flags & !ORC_HAS_META != 0 {
            return Err(invalid(format!("gORC flags {flags:#04x}")));
        }
        let len = BigEndian::read_u32(&p[1..5]) as usize;
        let rest = &p[5..];
        if len > rest.len() {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!("gORC colours of {len} bytes, {} present", rest.len()),
            ));
        }
        let (colors, meta) = rest.split_at(len);
        let has_meta = flags & ORC_HAS_META != 0;
        if !has_meta && !meta.is_empty() {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                "bytes after the gORC colours",
            ));
        }
        Ok(OriginalColors {
            colors: colors.to_vec(),
            metadata: has_meta.then(|| meta.to_vec()),
        })
    }
}
