//! A stable, deterministic GPU radix sort of `(u32 key, u32 value)` pairs, for binning
//! Gaussians into tiles on the GPU: pairs are emitted in Gaussian order and keyed by tile,
//! and stability keeps each tile's Gaussians in stored order, as the CPU's binning does.
//!
//! LSD radix sort with digits of up to 11 bits, `ceil(key_bits / 11)` passes, each of
//! three kernels (`shaders/sort_*.wgsl`): per-block digit counts, one exclusive scan of
//! them, and a scatter that ranks equal digits by position (a bitonic sort of the block),
//! never by atomic counters, so the output is the same on every run and every adapter.
//! Wide digits because passes, not items, are what a frame's sort costs: a 768×512
//! frame's 1536 tile keys take one pass of 11 bits instead of two of 8. The live length
//! is a `u32` on the GPU (written by an earlier kernel), which the host never reads: every
//! kernel is dispatched for the buffers' capacity and ignores the items past the count.

use super::Kernel;
use super::{Error, ErrorKind, Result};
use wgpu::util::DeviceExt;

/// Items each invocation of a scan's blocks sums, in the forward half's scan of Gaussians
/// and in this sort's scan of bins: a block is `GROUP · SCAN_PER` items, one workgroup.
pub const SCAN_PER: u32 = 16;

/// Items per block, one workgroup's share (`SORT_BLOCK` of the shaders' prelude).
pub const BLOCK: u32 = 1024;
/// Byte offset of `ranges` in the shaders' `SortParams` (eight `u32`: shift, blocks,
/// capacity, bits, ranges, padding), checked against the WGSL by a test of `gpu`.
pub(crate) const RANGES_AT: u64 = 16;

/// Invocations per workgroup of every sort kernel (`SORT_WG` of the shaders).
const WORKGROUP: u64 = 256;

/// Bits of the widest digit: its `2^11` bins fill 8 KiB of workgroup memory in the
/// histogram and the scatter.
pub const MAX_DIGIT_BITS: u32 = 11;

/// The passes for keys below `2^key_bits`, and the bits of each pass's digit: as few
/// passes as digits of [`MAX_DIGIT_BITS`] allow, the bits spread evenly over them (the
/// fewer bins, the less each block's histogram holds).
fn digits(key_bits: u32) -> (u32, u32) {
    let passes = key_bits.div_ceil(MAX_DIGIT_BITS);
    (passes, key_bits.div_ceil(passes.max(1)))
}

/// The pipelines, built once per device.
pub struct RadixSort {
    histogram: Kernel,
    /// `sort_scan.wgsl`'s `chunks` and `apply`, sharing one bind group.
    scan: [Kernel; 2],
    scatter: Kernel,
}

impl RadixSort {
    pub fn new(device: &wgpu::Device) -> RadixSort {
        RadixSort {
            histogram: Kernel::new(
                device,
                "sort_histogram",
                &shader!("device/sort_common", "device/sort_histogram"),
                2,
                1,
            ),
            scan: Kernel::entries(
                device,
                "sort_scan",
                &shader!("device/sort_common", "device/sort_scan"),
                ["chunks", "apply"],
                0,
                3,
            ),
            scatter: Kernel::new(
                device,
                "sort_scatter",
                &shader!("device/sort_common", "device/sort_scatter"),
                4,
                2,
            ),
        }
    }
}

/// The bind groups of one pass (one digit), and its uniform block.
struct Pass {
    histogram: wgpu::BindGroup,
    scan: wgpu::BindGroup,
    scatter: wgpu::BindGroup,
    params: wgpu::Buffer,
}

/// Scratch buffers and bind groups for sorting `keys`/`values` (each `capacity` u32s,
/// `STORAGE | COPY_SRC | COPY_DST`) whose live length is `min(count[0], capacity)`.
///
/// After [`SortPlan::record`] the first `min(count[0], capacity)` entries of the buffers
/// that [`SortPlan::sorted`] names are the pairs sorted by key, equal keys in input order;
/// the entries past them, and the other buffers, are unspecified.
pub struct SortPlan {
    passes: Vec<Pass>,
    /// Workgroups per dispatch of the per-block kernels, a 2D grid covering every block.
    groups: (u32, u32),
    /// Workgroups of the scan's per-chunk kernels.
    scan_groups: (u32, u32),
    /// Where the last pass writes: the caller's keys and values after an even pass count,
    /// the plan's scratch after an odd one (read there rather than copied back: a copy
    /// costs a frame as much as a dispatch).
    sorted: (wgpu::Buffer, wgpu::Buffer),
    /// The histogram and the scan's chunk sums, for [`SortPlan::write_ranges`].
    scan_buffers: Option<(wgpu::Buffer, wgpu::Buffer)>,
    /// Bits of each pass's digit.
    digit_bits: u32,
}

impl SortPlan {
    /// Plan the sort of keys below `2^key_bits` (`key_bits ≤ 32`; fewer bits, fewer
    /// passes). Refuses, with [`ErrorKind::LimitExceeded`], buffers or scratch the device
    /// cannot bind or dispatch over, and, with [`ErrorKind::InvalidValue`], `key_bits`
    /// above 32 or buffers smaller than `capacity` (`count` needs 4 bytes). The plan's
    /// bind groups belong to `sort`'s pipelines: record it with the same `sort`.
    pub fn new(
        gpu: &super::Gpu,
        sort: &RadixSort,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        count: &wgpu::Buffer,
        capacity: u32,
        key_bits: u32,
    ) -> Result<SortPlan> {
        if key_bits > 32 {
            return Err(Error::new(
                ErrorKind::InvalidValue,
                format!("radix sort of {key_bits}-bit keys (at most 32)"),
            ));
        }
        let bytes = u64::from(capacity) * 4;
        let (passes, digit_bits) = digits(key_bits);
        let bins = 1u64 << digit_bits;
        let device = &gpu.device;
        let max_binding = gpu.max_binding;
        let blocks = capacity.div_ceil(BLOCK);
        let hist_bytes = bins * u64::from(blocks) * 4;
        let max_groups = gpu.max_groups.max(1);
        let gx = blocks.clamp(1, max_groups);
        let groups = (gx, blocks.div_ceil(gx));
        if bytes > max_binding || hist_bytes > max_binding || groups.1 > max_groups {
            return Err(Error::new(
                ErrorKind::LimitExceeded,
                format!("a radix sort of {capacity} pairs exceeds what the GPU can bind"),
            ));
        }
        if keys.size() < bytes || values.size() < bytes || count.size() < 4 {
            return Err(Error::new(
                ErrorKind::InvalidValue,
                "radix sort buffers smaller than their capacity",
            ));
        }
        // Nothing to sort, or every key is 0 (a stable sort is then the identity).
        if capacity == 0 || passes == 0 {
            return Ok(SortPlan {
                passes: Vec::new(),
                groups: (0, 0),
                scan_groups: (0, 0),
                sorted: (keys.clone(), values.clone()),
                scan_buffers: None,
                digit_bits: 0,
            });
        }
        let storage = |size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("sort scratch"),
                size,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let (scratch_keys, scratch_values, hist) =
            (storage(bytes), storage(bytes), storage(hist_bytes));
        // The scan's chunks of the histogram, one workgroup each.
        let chunks = (bins * u64::from(blocks)).div_ceil(WORKGROUP * u64::from(SCAN_PER)) as u32;
        let chunk_sums = storage(u64::from(chunks.max(1)) * 4);
        // The scan's ranges output until `write_ranges` names one: never written.
        let no_ranges = storage(4);
        let cx = chunks.clamp(1, max_groups);
        let scan_groups = (cx, chunks.div_ceil(cx).max(1));
        // Pass p reads `from` and writes `to`, alternating caller → scratch → caller. The
        // bind groups keep the scratch buffers alive (wgpu counts references).
        let (mut from, mut to) = ((keys, values), (&scratch_keys, &scratch_values));
        let passes = (0..passes)
            .map(|p| {
                // `SortParams`: shift, blocks, capacity, bits, ranges (none yet), padding.
                let params = [p * digit_bits, blocks, capacity, digit_bits, 0, 0, 0, 0u32];
                let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("sort params"),
                    contents: bytemuck::cast_slice(&params),
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                });
                let pass = Pass {
                    histogram: sort
                        .histogram
                        .bind(device, &[&params, count, from.0, &hist]),
                    scan: sort.scan[0].bind(device, &[&params, &hist, &chunk_sums, &no_ranges]),
                    scatter: sort
                        .scatter
                        .bind(device, &[&params, count, from.0, from.1, &hist, to.0, to.1]),
                    params,
                };
                std::mem::swap(&mut from, &mut to);
                pass
            })
            .collect::<Vec<_>>();
        Ok(SortPlan {
            passes,
            groups,
            scan_groups,
            sorted: (from.0.clone(), from.1.clone()),
            scan_buffers: Some((hist, chunk_sums)),
            digit_bits,
        })
    }

    /// Have the sort also write, into `out[0..=n]`, the first sorted slot of each key
    /// `0..=n` (`out[n]` the live count): where the keys are tiles, each tile's range of
    /// the sorted pairs, which then needs no dispatch of its own. Only a sort of one pass
    /// can, whose digit is the whole key; the caller promises every key is below `n`.
    /// Returns whether it will (false: one pass is not enough for `n` keys, or `out`
    /// holds fewer than `n + 1` u32s), for the next [`SortPlan::record`] on.
    pub fn write_ranges(
        &mut self,
        gpu: &super::Gpu,
        sort: &RadixSort,
        out: &wgpu::Buffer,
        n: u32,
    ) -> bool {
        let (Some((hist, chunk_sums)), [pass]) = (&self.scan_buffers, &mut self.passes[..]) else {
            return false;
        };
        if n == 0 || u64::from(n) > 1 << self.digit_bits || out.size() < (u64::from(n) + 1) * 4 {
            return false;
        }
        gpu.queue
            .write_buffer(&pass.params, RANGES_AT, bytemuck::bytes_of(&n));
        pass.scan = sort.scan[0].bind(&gpu.device, &[&pass.params, hist, chunk_sums, out]);
        true
    }

    /// The keys and values buffers that hold the sorted pairs after [`SortPlan::record`].
    pub fn sorted(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.sorted.0, &self.sorted.1)
    }

    /// Record the whole sort into `encoder`: one compute pass (wgpu orders the dispatches
    /// that write and then read a buffer).
    pub fn record(&self, sort: &RadixSort, encoder: &mut wgpu::CommandEncoder) {
        if self.passes.is_empty() {
            return;
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("radix sort"),
            timestamp_writes: None,
        });
        for p in &self.passes {
            sort.histogram
                .dispatch(&mut pass, &p.histogram, self.groups);
            sort.scan[0].dispatch(&mut pass, &p.scan, self.scan_groups);
            sort.scan[1].dispatch(&mut pass, &p.scan, self.scan_groups);
            sort.scatter.dispatch(&mut pass, &p.scatter, self.groups);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_optim::rng::SplitMix64;

    use super::super::tests::gpu;

    /// The pipelines, failing the test on any shader or pipeline error.
    fn kernels(gpu: &super::super::Gpu) -> RadixSort {
        gpu.checked(|| Ok(RadixSort::new(&gpu.device))).unwrap()
    }

    fn buffer(gpu: &super::super::Gpu, data: &[u32]) -> wgpu::Buffer {
        gpu.storage(bytemuck::cast_slice(data))
    }

    fn read(gpu: &super::super::Gpu, buf: &wgpu::Buffer, len: usize) -> Vec<u32> {
        let enc = gpu.encoder();
        let [bytes] = gpu.read_back(enc, [buf]).unwrap();
        bytemuck::cast_slice::<u8, u32>(&bytes)[..len].to_vec()
    }

    /// Sort `keys` (values: their indices) on the GPU with `count` live pairs and check the
    /// live head against the CPU's stable sort of the first `min(count, len)` pairs.
    fn check(gpu: &super::super::Gpu, sort: &RadixSort, keys: &[u32], count: u32, key_bits: u32) {
        let capacity = keys.len() as u32;
        let values: Vec<u32> = (0..capacity).collect();
        let (kb, vb, cb) = (
            buffer(gpu, keys),
            buffer(gpu, &values),
            buffer(gpu, &[count]),
        );
        let plan = SortPlan::new(gpu, sort, &kb, &vb, &cb, capacity, key_bits).unwrap();
        let mut enc = gpu.encoder();
        plan.record(sort, &mut enc);
        gpu.submit([enc.finish()]);
        let live = count.min(capacity) as usize;
        let mut want: Vec<(u32, u32)> = keys[..live].iter().copied().zip(values).collect();
        want.sort_by_key(|&(k, _)| k);
        let (sk, sv) = plan.sorted();
        let got: Vec<(u32, u32)> = read(gpu, sk, live)
            .into_iter()
            .zip(read(gpu, sv, live))
            .collect();
        if let Some(i) = (0..live).find(|&i| got[i] != want[i]) {
            panic!(
                "n={capacity} count={count} bits={key_bits}: at {i} got {:?}, want {:?}",
                got[i], want[i]
            );
        }
    }

    /// `n` keys below `2^bits` drawn from a pool of about `n / 8` values, so that most
    /// keys repeat, yet spread over every digit.
    fn random_keys(rng: &mut SplitMix64, n: usize, bits: u32) -> Vec<u32> {
        let mask = if bits == 32 {
            u32::MAX
        } else {
            (1u32 << bits) - 1
        };
        let pool: Vec<u32> = (0..n / 8 + 1)
            .map(|_| rng.next_u64() as u32 & mask)
            .collect();
        (0..n)
            .map(|_| pool[(rng.next_u64() % pool.len() as u64) as usize])
            .collect()
    }

    #[test]
    fn matches_a_stable_cpu_sort() {
        let Some(gpu) = gpu() else { return };
        let sort = kernels(&gpu);
        let mut rng = SplitMix64::new(7);
        // One pass of 1, 5, 8 and 11 bits, two of 6, 8 and 11, three of 8 and of 11.
        for bits in [1, 5, 8, 11, 12, 16, 22, 24, 32] {
            for n in [0, 1, 255, 1024, 1025, 100_000] {
                let keys = random_keys(&mut rng, n, bits);
                check(&gpu, &sort, &keys, n as u32, bits);
            }
        }
    }

    #[test]
    fn digits_are_as_few_and_as_even_as_the_width_allows() {
        assert_eq!(digits(0), (0, 0));
        assert_eq!(digits(1), (1, 1));
        assert_eq!(digits(11), (1, 11));
        assert_eq!(digits(12), (2, 6));
        assert_eq!(digits(16), (2, 8));
        assert_eq!(digits(23), (3, 8));
        assert_eq!(digits(32), (3, 11));
    }

    #[test]
    fn a_one_pass_sort_writes_the_ranges_of_its_keys() {
        let Some(gpu) = gpu() else { return };
        let sort = kernels(&gpu);
        let mut rng = SplitMix64::new(13);
        // Fewer keys than bins, as many, a live count short of the capacity, and none.
        for (n, len, count) in [
            (5u32, 3000usize, 3000u32),
            (1536, 100_000, 100_000),
            (2048, 5000, 3001),
            (1536, 4096, 0),
        ] {
            let keys: Vec<u32> = (0..len)
                .map(|_| (rng.next_u64() % u64::from(n)) as u32)
                .collect();
            let values: Vec<u32> = (0..len as u32).collect();
            let bits = 32 - (n - 1).leading_zeros();
            let (kb, vb, cb) = (
                buffer(&gpu, &keys),
                buffer(&gpu, &values),
                buffer(&gpu, &[count]),
            );
            let out = buffer(&gpu, &vec![u32::MAX; n as usize + 1]);
            let mut plan = SortPlan::new(&gpu, &sort, &kb, &vb, &cb, len as u32, bits).unwrap();
            assert!(plan.write_ranges(&gpu, &sort, &out, n));
            let mut enc = gpu.encoder();
            plan.record(&sort, &mut enc);
            gpu.submit([enc.finish()]);
            // want[d]: the live keys below d.
            let mut want = vec![0u32; n as usize + 1];
            for &k in &keys[..(count as usize).min(len)] {
                want[k as usize + 1] += 1;
            }
            for d in 1..want.len() {
                want[d] += want[d - 1];
            }
            assert_eq!(
                read(&gpu, &out, want.len()),
                want,
                "{n} keys, count {count}"
            );
        }
        // Keys of two passes, or too small an output: the plan says it cannot.
        let (k, v, c) = (
            buffer(&gpu, &[0; 16]),
            buffer(&gpu, &[0; 16]),
            buffer(&gpu, &[16]),
        );
        let out = buffer(&gpu, &[0; 4]);
        let mut two = SortPlan::new(&gpu, &sort, &k, &v, &c, 16, 12).unwrap();
        assert!(!two.write_ranges(&gpu, &sort, &out, 3));
        let mut one = SortPlan::new(&gpu, &sort, &k, &v, &c, 16, 4).unwrap();
        assert!(!one.write_ranges(&gpu, &sort, &out, 16));
        assert!(!one.write_ranges(&gpu, &sort, &out, 17));
        assert!(one.write_ranges(&gpu, &sort, &out, 3));
    }

    #[test]
    fn ignores_pairs_past_the_count() {
        let Some(gpu) = gpu() else { return };
        let sort = kernels(&gpu);
        let mut rng = SplitMix64::new(11);
        for (n, count, bits) in [
            (5000, 3001, 16),
            (5000, 0, 16),
            (3000, 1024, 11),
            (3000, 2047, 24),
        ] {
            let keys = random_keys(&mut rng, n, bits);
            check(&gpu, &sort, &keys, count, bits);
        }
        // A count beyond the capacity sorts the whole buffer.
        let keys = random_keys(&mut rng, 2000, 16);
        check(&gpu, &sort, &keys, 2100, 16);
    }

    #[test]
    fn sorted_and_reversed_input() {
        let Some(gpu) = gpu() else { return };
        let sort = kernels(&gpu);
        let n = 10_000u32;
        let sorted: Vec<u32> = (0..n).map(|i| i / 3).collect();
        let reversed: Vec<u32> = sorted.iter().rev().copied().collect();
        for bits in [12, 16] {
            check(&gpu, &sort, &sorted, n, bits);
            check(&gpu, &sort, &reversed, n, bits);
        }
        // One key for everything: the values must come back in order.
        check(&gpu, &sort, &vec![5; 3000], 3000, 16);
    }

    #[test]
    fn refuses_what_it_cannot_sort() {
        let Some(gpu) = gpu() else { return };
        let sort = kernels(&gpu);
        let (k, v, c) = (
            buffer(&gpu, &[0; 16]),
            buffer(&gpu, &[0; 16]),
            buffer(&gpu, &[0]),
        );
        let plan = |capacity, bits| SortPlan::new(&gpu, &sort, &k, &v, &c, capacity, bits);
        let kind = |r: Result<SortPlan>| r.err().map(|e| e.kind());
        assert_eq!(kind(plan(16, 33)), Some(ErrorKind::InvalidValue));
        assert_eq!(kind(plan(17, 16)), Some(ErrorKind::InvalidValue));
        // 16 GiB per buffer: beyond any adapter's storage binding.
        assert_eq!(kind(plan(u32::MAX, 16)), Some(ErrorKind::LimitExceeded));
        assert!(plan(16, 32).is_ok());
        assert!(plan(0, 16).is_ok());
    }
}
