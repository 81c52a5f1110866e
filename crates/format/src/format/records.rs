//! Records: the attributes exactly as stored (integer codes plus quantizers), and their
//! lossless link to the float [`Scene`](crate::model::Scene).

use super::angle;
use super::context::{self, Coding, Footprint};
use super::error::{invalid, Error, ErrorKind, Result};
use super::footprint;
use super::header::{
    Header, VERSION_MINOR_CODED, VERSION_MINOR_CODED_RAW, VERSION_MINOR_FOOTPRINT,
    VERSION_MINOR_SHAPED,
};
use super::limits::{AllocBudget, Limits};
use super::quant::{self, Quantizer};
use crate::model::{CovParam, GaussianSet, Scene, WeightRule};
use byteorder::{BigEndian, ByteOrder};

/// Payload compression method of an attribute chunk.
pub const METHOD_STORED: u8 = 0;
pub const METHOD_ZSTD: u8 = 1;
/// Predicted, context-modelled and range-coded (spec §5.4; version 1.1).
pub const METHOD_CODED: u8 = 2;
/// Method 2's predictions with the bits that contexts do not help with raw, decoded with
/// fewer decisions (spec §5.4.4; version 1.6). What the encoder writes.
pub const METHOD_CODED_RAW: u8 = 3;
/// Method 3 and angles at the precision of their shape (spec §5.4.5; version 1.7): what
/// the encoder writes where it shapes the angles.
pub const METHOD_SHAPED: u8 = 4;
/// Method 3's coding with contexts per footprint class, for colours stored at the
/// precision of their footprint (spec §5.4.6; version 1.8): what the encoder writes for
/// `GCOL` in `sum` files.
pub const METHOD_FOOTPRINT: u8 = 5;

/// The coded methods: each coding, its method byte, and the least minor version of a
/// file that holds it (§2.5). Newest last.
const CODED: [(Coding, u8, u8); 4] = [
    (Coding::Method2, METHOD_CODED, VERSION_MINOR_CODED),
    (Coding::Method3, METHOD_CODED_RAW, VERSION_MINOR_CODED_RAW),
    (Coding::Method4, METHOD_SHAPED, VERSION_MINOR_SHAPED),
    (Coding::Method5, METHOD_FOOTPRINT, VERSION_MINOR_FOOTPRINT),
];

/// The newest coded method that a file of minor version `minor` may hold: method 5 from
/// 1.8, 4 from 1.7, 3 from 1.6, 2 from 1.1, none before. (A file of 1.6 may hold method
/// 2 too.)
pub fn newest_coding(minor: u8) -> Option<Coding> {
    CODED.iter().rev().find(|c| minor >= c.2).map(|c| c.0)
}

/// The least minor version of a file with a payload of `method` (§2.5).
pub fn minor_for_method(method: u8) -> u8 {
    CODED.iter().find(|c| c.1 == method).map_or(0, |c| c.2)
}

/// The coding of a coded method byte.
fn coding(method: u8) -> Option<Coding> {
    CODED.iter().find(|c| c.1 == method).map(|c| c.0)
}

/// The method byte of a coding.
fn method_of(coding: Coding) -> u8 {
    CODED
        .iter()
        .find(|c| c.0 == coding)
        .map(|c| c.1)
        .expect("every coding is in the table")
}

/// Bytes in front of the packed data for an attribute of `components` components.
pub const fn attribute_preamble_len(components: usize) -> usize {
    1 + 9 * components + 1 + 4
}

/// One attribute (positions, covariance, colour or opacity) of every Gaussian, as codes.
#[derive(Clone, Debug, PartialEq)]
pub struct Attribute {
    /// One quantizer per component.
    pub quantizers: Vec<Quantizer>,
    /// Planar codes: component 0 of every Gaussian, then component 1, …
    pub codes: Vec<u32>,
    /// The offset of §5.4.5 where component 2 holds angles at the precision of their
    /// shape (each code the middle of its bucket, [`crate::format::angle`]), so that method
    /// 4 may code them in mode 5; `None` for every other attribute.
    pub shape: Option<f32>,
    /// The base of §5.4.6 where the codes are of colours stored at the precision of their
    /// footprint (method 5, [`crate::format::footprint`]): each value is then the colour
    /// times `2^k`, `k` the Gaussian's class, and [`Records::to_scene`] takes the `2^k`
    /// back. `None` for every other attribute, whose values are what they say.
    pub footprint: Option<i8>,
}

impl Attribute {
    pub fn components(&self) -> usize {
        self.quantizers.len()
    }

    pub fn count(&self) -> usize {
        self.codes.len().checked_div(self.components()).unwrap_or(0)
    }

    /// Quantize `count` records of `C` components with the given quantizers.
    pub fn quantize<const C: usize>(values: &[[f32; C]], quantizers: [Quantizer; C]) -> Attribute {
        let mut codes = Vec::with_capacity(values.len() * C);
        for (c, q) in quantizers.iter().enumerate() {
            codes.extend(values.iter().map(|v| q.quantize(v[c])));
        }
        Attribute {
            quantizers: quantizers.to_vec(),
            codes,
            shape: None,
            footprint: None,
        }
    }

    /// Quantize with `bits[c]`-bit quantizers fitted to each component's range.
    pub fn fit<const C: usize>(values: &[[f32; C]], bits: [u8; C]) -> Attribute {
        let qs = std::array::from_fn(|c| Quantizer::fit(bits[c], values.iter().map(|v| v[c])));
        Attribute::quantize(values, qs)
    }

    /// A `log-scale-rotation` covariance with its angles shaped (§5.4.5,
    /// [`angle::shape`]): scales at `scale_bits`, the angle stored [`angle::EXTRA_BITS`]
    /// above `angle_bits`, at the noise of `angle_bits` uniform bits.
    pub fn shaped_angles(
        cov: &[[f32; 3]],
        colors: &[[f32; 3]],
        scale_bits: u8,
        angle_bits: u8,
    ) -> Attribute {
        let depth = angle_bits
            .saturating_add(angle::EXTRA_BITS)
            .min(quant::MAX_BITS);
        let mut a = Attribute::fit(cov, [scale_bits, scale_bits, depth]);
        a.shape = angle::shape(cov, colors, &a.quantizers, &mut a.codes, angle_bits);
        a
    }

    /// Colours of `count` Gaussians stored at the precision of their footprint (§5.4.6):
    /// `colors[i]·2^k` quantized with `bits`-bit quantizers fitted to their range, `k`
    /// the class of `sizes[i]` ([`footprint::sizes`] of the stored covariance) under the
    /// base the reference encoder writes ([`footprint::base_for`]).
    pub fn footprint_colors(colors: &[[f32; 3]], sizes: &[i32], bits: u8) -> Attribute {
        let base = footprint::base_for(sizes);
        let stored: Vec<[f32; 3]> = colors
            .iter()
            .zip(sizes)
            .map(|(c, &s)| {
                let g = footprint::gain(footprint::class(s, base));
                c.map(|v| v * g)
            })
            .collect();
        let mut a = Attribute::fit(&stored, [bits; 3]);
        a.footprint = Some(base);
        a
    }

    /// Dequantize into records of `C` components (`C` must equal `components()`).
    pub fn values<const C: usize>(&self) -> Vec<[f32; C]> {
        assert_eq!(
            C,
            self.components(),
            "attribute has {} components",
            self.components()
        );
        let n = self.count();
        let mut out = vec![[0f32; C]; n];
        for (c, q) in self.quantizers.iter().enumerate() {
            let plane = &self.codes[c * n..(c + 1) * n];
            // Colour and covariance codes take a few hundred values at most: looked up,
            // each is computed once rather than once per Gaussian (its f64 division).
            let values = q.lookup(n, |code| q.dequantize(code));
            for (o, &code) in out.iter_mut().zip(plane) {
                o[c] = values.get(code);
            }
        }
        out
    }

    /// Serialize as an attribute chunk payload (spec §5.1), choosing whichever of stored
    /// and zstd at `level` is smaller: a payload every 1.0 decoder reads.
    pub fn to_payload(&self, zstd_level: i32) -> Result<Vec<u8>> {
        self.to_payload_with(zstd_level, false)
    }

    /// A payload of `method` (2 to 5) in the given modes, for the spec's worked examples
    /// and tests; `None` where the method is not a coded one or the modes are not valid
    /// for this attribute (mode 5 where its angles are not shaped).
    /// Method 5 takes `sizes` ([`footprint::sizes`] of the covariance) and an
    /// attribute with a [`footprint`](Self::footprint) base.
    #[doc(hidden)]
    pub fn to_coded_payload(
        &self,
        modes: &[u8],
        method: u8,
        sizes: Option<&[i32]>,
    ) -> Option<Vec<u8>> {
        let c = coding(method)?;
        let classes = match (c, self.footprint, sizes) {
            (Coding::Method5, Some(base), Some(s)) if s.len() == self.count() => {
                Some((base, footprint::classes(s, base)))
            }
            (Coding::Method5, _, _) => return None,
            _ => None,
        };
        let ok = modes.len() == self.components()
            && context::check_modes(modes, c).is_ok()
            && (!modes.contains(&context::MODE_SHAPED)
                || self.shape.is_some_and(|o| {
                    context::shaped(&self.codes, self.count(), &self.quantizers, o)
                }));
        ok.then(|| {
            let data = context::encode_with_modes(
                &self.codes,
                self.count(),
                &self.quantizers,
                modes,
                self.shape,
                classes.as_ref().map(|(base, k)| Footprint {
                    base: *base,
                    classes: k,
                }),
                c,
            );
            self.payload(method, &data)
        })
    }

    /// [`to_payload`](Self::to_payload), and with `coded` also method 3 (§5.4.4), of the
    /// three whichever is smallest.
    /// A shaped attribute ([`Attribute::shape`]) is tried in method 4 too.
    pub fn to_payload_with(&self, zstd_level: i32, coded: bool) -> Result<Vec<u8>> {
        self.to_payload_coded(zstd_level, coded.then_some(Coding::Method4))
    }

    /// [`to_payload`](Self::to_payload), and with `coded` also that coded method, of the
    /// three whichever is smallest: for a file whose minor version says which methods it
    /// may hold ([`newest_coding`]). Method 4 is tried only for a shaped attribute, and
    /// method 3 beside it, so that only a payload with shaped angles needs version 1.7.
    ///
    /// An attribute of colours by footprint has only method 5
    /// ([`to_footprint_payload`](Self::to_footprint_payload)), and is refused here.
    pub fn to_payload_coded(&self, zstd_level: i32, coded: Option<Coding>) -> Result<Vec<u8>> {
        if self.footprint.is_some() {
            return Err(invalid(
                "colours stored by footprint are written with their covariance (method 5)",
            ));
        }
        let packed = quant::pack(&self.codes, self.count(), &self.quantizers);
        let zipped = zstd::bulk::compress(&packed, zstd_level)?;
        let (mut method, mut data) = if zipped.len() < packed.len() {
            (METHOD_ZSTD, zipped)
        } else {
            (METHOD_STORED, packed)
        };
        let shaped =
            self.shape.is_some() && matches!(coded, Some(Coding::Method4) | Some(Coding::Method5));
        let coded = match coded {
            Some(Coding::Method4) | Some(Coding::Method5) => Some(Coding::Method3),
            c => c,
        };
        for c in coded.into_iter().chain(shaped.then_some(Coding::Method4)) {
            let d = context::encode(
                &self.codes,
                self.count(),
                &self.quantizers,
                self.shape,
                None,
                c,
            );
            if d.len() < data.len() {
                (method, data) = (method_of(c), d);
            }
        }
        Ok(self.payload(method, &data))
    }

    /// The payload of colours by footprint (method 5, §5.4.6), for Gaussians of footprint
    /// `sizes` ([`footprint::sizes`] of the covariance it is written with).
    pub fn to_footprint_payload(&self, sizes: &[i32]) -> Result<Vec<u8>> {
        let base = self
            .footprint
            .ok_or_else(|| invalid("method 5 for an attribute not stored by footprint"))?;
        if self.components() != 3 || sizes.len() != self.count() {
            return Err(invalid(format!(
                "colours by footprint of {} components for {} sizes",
                self.components(),
                sizes.len()
            )));
        }
        let classes = footprint::classes(sizes, base);
        let fp = Footprint {
            base,
            classes: &classes,
        };
        let data = context::encode(
            &self.codes,
            self.count(),
            &self.quantizers,
            None,
            Some(fp),
            Coding::Method5,
        );
        Ok(self.payload(METHOD_FOOTPRINT, &data))
    }

    /// The preamble (§5.1) and `data`.
    fn payload(&self, method: u8, data: &[u8]) -> Vec<u8> {
        let packed_len = quant::packed_len(self.count() as u64, &self.quantizers);
        let mut out = Vec::with_capacity(attribute_preamble_len(self.components()) + data.len());
        out.push(self.components() as u8);
        for q in &self.quantizers {
            out.push(q.bits);
            out.extend(q.min.to_be_bytes());
            out.extend(q.max.to_be_bytes());
        }
        out.push(method);
        out.extend((packed_len as u32).to_be_bytes());
        out.extend_from_slice(data);
        out
    }

    /// Parse one attribute payload of `count` records (default [`Limits`]): the entry of
    /// the spec's worked examples and of the fuzz target of methods 2 and 3.
    #[doc(hidden)]
    pub fn from_payload(payload: &[u8], components: usize, count: u32) -> Result<Attribute> {
        Self::parse_standalone(payload, components, count, &Limits::default(), None)
    }

    /// [`from_payload`](Self::from_payload) of colours, with the footprint sizes of the
    /// file's covariance that a method-5 payload needs (§5.4.6).
    #[doc(hidden)]
    pub fn from_colour_payload(payload: &[u8], count: u32, sizes: &[i32]) -> Result<Attribute> {
        Self::parse_standalone(payload, 3, count, &Limits::default(), Some(sizes))
    }

    /// [`parse`](Self::parse) with its own allocation budget, for a payload found outside
    /// the normal chunk sequence (inside `gORC`).
    /// `sizes` as for [`parse`](Self::parse).
    pub fn parse_standalone(
        p: &[u8],
        components: usize,
        count: u32,
        limits: &Limits,
        sizes: Option<&[i32]>,
    ) -> Result<Attribute> {
        Self::parse(
            p,
            components,
            count,
            limits,
            &mut AllocBudget::new(limits),
            sizes,
        )
    }

    /// Parse an attribute chunk payload holding `count` records of `components` components.
    /// Sizes are checked against `limits` and `budget` before anything is allocated.
    /// `sizes`: the footprint size of every Gaussian ([`footprint::sizes`] of the file's
    /// `log-scale-rotation` covariance), which a method-5 payload needs and is refused
    /// without; `None` where there is no such covariance.
    pub fn parse(
        p: &[u8],
        components: usize,
        count: u32,
        limits: &Limits,
        budget: &mut AllocBudget,
        sizes: Option<&[i32]>,
    ) -> Result<Attribute> {
        let pre = attribute_preamble_len(components);
        if p.len() < pre {
            return Err(Error::new(
                ErrorKind::BadChunkLength,
                format!("{} bytes, shorter than its {pre}-byte preamble", p.len()),
            ));
        }
        if usize::from(p[0]) != components {
            return Err(invalid(format!(
                "{} components, expected {components}",
                p[0]
            )));
        }
        let quantizers: Vec<Quantizer> = p[1..1 + 9 * components]
            .chunks_exact(9)
            .map(|d| Quantizer {
                bits: d[0],
                min: BigEndian::read_f32(&d[1..5]),
                max: BigEndian::read_f32(&d[5..9]),
            })
            .collect();
        for q in &quantizers {
            q.validate()?;
        }
        let method = p[pre - 5];
        let declared = u64::from(BigEndian::read_u32(&p[pre - 4..pre]));
        let expected = quant::packed_len(u64::from(count), &quantizers);
        if declared != expected {
            return Err(invalid(format!(
                "packed length {declared}, expected {expected} for {count} records"
            )));
        }
        if expected > limits.max_decompressed {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!(
                    "{expected} packed bytes exceeds {}",
                    limits.max_decompressed
                ),
            ));
        }
        let data = &p[pre..];
        let zipped;
        let packed: &[u8] = match method {
            METHOD_STORED => {
                if data.len() as u64 != expected {
                    return Err(Error::new(
                        ErrorKind::BadChunkLength,
                        format!("{} stored bytes, expected {expected}", data.len()),
                    ));
                }
                data
            }
            METHOD_ZSTD => {
                budget.reserve(expected, "decompressed attribute")?;
                // A frame that would grow past `expected` fails instead of allocating more.
                zipped = zstd::bulk::decompress(data, expected as usize)
                    .map_err(|e| Error::new(ErrorKind::Decompression, e.to_string()))?;
                if zipped.len() as u64 != expected {
                    return Err(Error::new(
                        ErrorKind::Decompression,
                        format!("{} bytes decompressed, expected {expected}", zipped.len()),
                    ));
                }
                &zipped
            }
            METHOD_FOOTPRINT if components != 3 => {
                return Err(invalid(format!(
                    "compression method 5 for an attribute of {components} components"
                )))
            }
            METHOD_CODED | METHOD_CODED_RAW | METHOD_SHAPED | METHOD_FOOTPRINT => &[],
            m => return Err(invalid(format!("compression method {m}"))),
        };
        let ncodes = u64::from(count) * components as u64;
        budget.reserve(ncodes * 4, "attribute codes")?;
        let (codes, shape, footprint) = if let Some(c) = coding(method) {
            let d = context::decode(data, count as usize, &quantizers, c, sizes)?;
            (d.codes, d.shape, d.footprint)
        } else {
            (
                quant::unpack(packed, count as usize, &quantizers),
                None,
                None,
            )
        };
        if method == METHOD_ZSTD {
            budget.release(expected);
        }
        Ok(Attribute {
            quantizers,
            codes,
            shape,
            footprint,
        })
    }
}

/// The four attributes of a file plus its header: the whole stored image, codes and all.
#[derive(Clone, Debug, PartialEq)]
pub struct Records {
    pub header: Header,
    pub positions: Attribute,
    pub covariance: Attribute,
    pub colors: Attribute,
    /// `None`: no `GOPA` chunk, every opacity is 1.
    pub opacity: Option<Attribute>,
    /// The `GTRC` chunk (spec §6.6): `None`, the blended values are shown as they are.
    pub tone: Option<crate::model::ToneCurve>,
    /// [`WeightRule::Columns`] where the file has a `GCRW` chunk, [`WeightRule::Columns32`]
    /// where it has `GCRT` (spec §6.3.2).
    pub weights: WeightRule,
}

/// Bits per component an encoder spends on each attribute.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BitDepths {
    pub position: u8,
    /// The covariance's components; under `log-scale-rotation`, its two log-scales.
    pub covariance: u8,
    /// The angle of a `log-scale-rotation` covariance (its third component). Apart
    /// because its range is the encoder's choice: the stage-1 encoder keeps every angle
    /// within a quarter turn (`gsi::fit::params::canonical_rotation`), where one bit
    /// fewer than the scales already halves the step a free angle had. A `cholesky`
    /// covariance spends `covariance` on all three components.
    pub angle: u8,
    /// Angles at the precision of their Gaussian's shape (spec §5.4.5, method 4): the
    /// noise of `angle` uniform bits, in fewer ([`Attribute::shaped_angles`]).
    /// For `log-scale-rotation` only.
    pub angle_by_shape: bool,
    /// Colours at the precision of their footprint (spec §5.4.6, method 5): `color` bits
    /// over the range of the colours times `2^k`, each Gaussian's step halved for every
    /// doubling of its side ([`Attribute::footprint_colors`]). For `log-scale-rotation`
    /// only.
    pub color_by_footprint: bool,
    pub color: u8,
    pub opacity: u8,
}

impl BitDepths {
    /// The depths of the three covariance components under `cov_param`: the angle of a
    /// `log-scale-rotation` covariance takes [`BitDepths::angle`].
    pub fn of_covariance(&self, cov_param: CovParam) -> [u8; 3] {
        let third = match cov_param {
            CovParam::LogScaleRotation => self.angle,
            CovParam::Cholesky => self.covariance,
        };
        [self.covariance, self.covariance, third]
    }
}

impl Default for BitDepths {
    fn default() -> Self {
        BitDepths {
            position: 16,
            covariance: 12,
            angle: 12,
            angle_by_shape: false,
            color_by_footprint: false,
            color: 8,
            opacity: 8,
        }
    }
}

impl Records {
    /// Quantize a scene with quantizers fitted to each component's range. Opacity is
    /// dropped when every value is 1, since its absence means exactly that.
    pub fn from_scene(scene: &Scene, bits: BitDepths) -> Records {
        let g = &scene.gaussians;
        assert!(g.is_consistent(), "inconsistent Gaussian set");
        let opacity = g
            .opacity
            .as_ref()
            .filter(|o| o.iter().any(|&a| a != 1.0))
            .map(|o| {
                let o: Vec<[f32; 1]> = o.iter().map(|&a| [a]).collect();
                Attribute::fit(&o, [bits.opacity])
            });
        let log_scales = scene.cov_param == CovParam::LogScaleRotation;
        let covariance = if bits.angle_by_shape && log_scales {
            Attribute::shaped_angles(&g.cov, &g.colors, bits.covariance, bits.angle)
        } else {
            Attribute::fit(&g.cov, bits.of_covariance(scene.cov_param))
        };
        let sizes = (bits.color_by_footprint && log_scales)
            .then(|| footprint::sizes(&covariance.quantizers, &covariance.codes).ok())
            .flatten();
        let colors = match sizes {
            Some(sizes) => Attribute::footprint_colors(&g.colors, &sizes, bits.color),
            None => Attribute::fit(&g.colors, [bits.color; 3]),
        };
        Records {
            header: Header::new(
                scene.width,
                scene.height,
                g.len() as u32,
                scene.blend,
                scene.cov_param,
            ),
            positions: Attribute::fit(&g.positions, [bits.position; 2]),
            covariance,
            colors,
            opacity,
            tone: scene.tone.clone(),
            weights: scene.weights,
        }
    }

    /// Dequantize into the float model.
    pub fn to_scene(&self) -> Scene {
        let h = &self.header;
        Scene {
            width: h.width,
            height: h.height,
            blend: h.blend,
            cov_param: h.cov_param,
            gaussians: GaussianSet {
                positions: self.positions.values(),
                cov: self.covariance.values(),
                colors: self.color_values(),
                opacity: self
                    .opacity
                    .as_ref()
                    .map(|a| a.values::<1>().into_iter().map(|[o]| o).collect()),
            },
            tone: self.tone.clone(),
            weights: self.weights,
        }
    }

    /// The colours of every Gaussian: the stored values, divided by `2^k` where they are
    /// stored by footprint (§5.4.6).
    pub fn color_values(&self) -> Vec<[f32; 3]> {
        let mut colors: Vec<[f32; 3]> = self.colors.values();
        if let Some(steps) = self.color_steps() {
            for (c, s) in colors.iter_mut().zip(steps) {
                *c = c.map(|v| v * s);
            }
        }
        colors
    }

    /// `2^−k` of each Gaussian where the colours are stored by footprint (§5.4.6): a
    /// colour is its stored value times this, exactly. `None` for colours stored as
    /// they are.
    pub fn color_steps(&self) -> Option<Vec<f32>> {
        let base = self.colors.footprint?;
        let sizes = footprint::sizes(&self.covariance.quantizers, &self.covariance.codes).ok()?;
        Some(
            sizes
                .iter()
                .map(|&s| footprint::step(footprint::class(s, base)))
                .collect(),
        )
    }

    /// The payload of `attribute`, one of these records' own, as [`write_file`] writes
    /// it: colours stored by footprint in method 5 (they have no other), every other
    /// attribute by [`Attribute::to_payload_with`] with `coded`.
    ///
    /// [`write_file`]: crate::format::write_file
    pub fn attribute_payload(
        &self,
        attribute: &Attribute,
        zstd_level: i32,
        coded: bool,
    ) -> Result<Vec<u8>> {
        if attribute.footprint.is_none() {
            return attribute.to_payload_with(zstd_level, coded);
        }
        let sizes = self.footprint_sizes().ok_or_else(|| {
            invalid("colours stored by footprint need a log-scale-rotation covariance")
        })?;
        attribute.to_footprint_payload(&sizes)
    }

    /// The footprint sizes ([`footprint::sizes`]) that colours stored by footprint in a
    /// file of these records are read with: `None` where the covariance is not
    /// `log-scale-rotation`.
    pub fn footprint_sizes(&self) -> Option<Vec<i32>> {
        (self.header.cov_param == CovParam::LogScaleRotation)
            .then(|| footprint::sizes(&self.covariance.quantizers, &self.covariance.codes).ok())
            .flatten()
    }

    /// Quantize `colors` (one per Gaussian) as these records store their colours: by
    /// footprint at the colour depth where they are, else with quantizers fitted to
    /// their range at `bits`.
    pub fn quantize_colors(&self, colors: &[[f32; 3]], bits: u8) -> Attribute {
        let sizes = self.colors.footprint.and(self.footprint_sizes());
        match sizes {
            Some(sizes) if sizes.len() == colors.len() => {
                Attribute::footprint_colors(colors, &sizes, bits)
            }
            _ => Attribute::fit(colors, [bits; 3]),
        }
    }

    /// Reorder the Gaussians along a Morton curve over their position codes, so that
    /// neighbours in the stream are neighbours in the image and method 2 codes each
    /// centre as a short step (§5.4). Only for `sum` blending, where the order of the
    /// Gaussians does not change a pixel; an `alpha` file is left as it is. Clears the
    /// importance-ordered flag, which the new order no longer honours.
    pub fn sort_spatially(&mut self) {
        if self.header.blend != crate::model::Blend::Sum || !self.is_consistent() {
            return;
        }
        let n = self.header.count as usize;
        let (u, v) = self.positions.codes.split_at(n);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&i| (context::morton(u[i], v[i]), i));
        for a in [&mut self.positions, &mut self.covariance, &mut self.colors]
            .into_iter()
            .chain(self.opacity.as_mut())
        {
            a.codes = a
                .codes
                .chunks(n.max(1))
                .flat_map(|plane| order.iter().map(|&i| plane[i]))
                .collect();
        }
        self.header.flags &= !super::header::FLAG_IMPORTANCE_ORDERED;
    }

    /// True when every attribute holds `header.count` records of the right width.
    pub fn is_consistent(&self) -> bool {
        let n = self.header.count as usize;
        let ok = |a: &Attribute, c: usize| a.components() == c && a.codes.len() == n * c;
        ok(&self.positions, 2)
            && ok(&self.covariance, 3)
            && ok(&self.colors, 3)
            && self.opacity.as_ref().is_none_or(|a| ok(a, 1))
    }
}
