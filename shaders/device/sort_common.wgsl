// Shared by the three kernels of the stable LSD radix sort (`src/gpu/sort.rs`): the
// block shape and the per-pass uniform block. The host prepends it (after
// the contract constants) to each sort shader, since WGSL has no includes.
//
// A block is SORT_BLOCK items, handled by one workgroup of 256 invocations. Digits are
// up to 11 bits wide (`params.bits`), so that the tile keys of a 768×512 frame (1536
// tiles) sort in one pass: each pass is three dependent dispatches, and on a GPU every
// dependent dispatch costs microseconds whatever it does.

const SORT_WG: u32 = 256u;
// SORT_BLOCK, SORT_INDEX_BITS (its log2) and SORT_MAX_BINS (the widest digit's bins)
// come with the contract constants, from `sort`.
const SORT_ROUNDS: u32 = SORT_BLOCK / SORT_WG;

struct SortParams {
    // The digit of this pass is (key >> shift) & (2^bits - 1).
    shift: u32,
    // ceil(capacity / SORT_BLOCK): the columns of the digit-major histogram.
    blocks: u32,
    // Items the buffers hold; the live ones are the first min(count[0], capacity).
    capacity: u32,
    // Bits of this pass's digit, 1 to 11.
    bits: u32,
    // Where not 0, this pass's digit is the whole key, every key is below `ranges`, and
    // the scan also writes the first output slot of each key 0..=ranges into
    // `ranges_out` (the last one the live count): a tile list's ranges, without a
    // dispatch of their own.
    ranges: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

fn sort_bins() -> u32 {
    return 1u << params.bits;
}

fn digit_of(key: u32) -> u32 {
    return (key >> params.shift) & (sort_bins() - 1u);
}
