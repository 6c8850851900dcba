//! Deterministic per-pixel sampler: Owen-scrambled Sobol points (Burley 2020, "Practical
//! hash-based Owen scrambling", through the `sobol_burley` crate), seeded by a hash of the
//! render seed and the pixel so that every pixel's sample stream is independent of the thread
//! that renders it. Past 2^16 samples it continues with a freshly scrambled sequence per block
//! of 2^16.
//!
//! Only the first `SOBOL_DIMS` dimensions of a sample (the pixel position and the first five
//! bounces) are Sobol points; the rest of the path draws from a per-sample SplitMix64 stream
//! (Steele et al. 2014), as pbrt's padded samplers do. Five bounces rather than two: with the
//! Sobol dimensions computed eight at a time, the three more registers per sample cost less
//! than the hashes they replace and than the mispredicted branch of lanes switching between
//! Sobol and hash numbers at different depths (`next_n`), and the error is lower too
//! (`bench/README.md`, "Design measurements").

use super::Vec2;
use sobol_burley::parts;
use std::sync::OnceLock;
use wide::{f32x8, u32x8};

/// Dimensions served from Sobol points: 2 film + 5 bounces × 7 (light 3, BSDF 3, roulette 1),
/// so that a bounce's seven numbers all come from Sobol points or all from the hash (`next_n`).
const SOBOL_DIMS: u32 = 37;
/// Registers of eight dimensions (one AVX register each) computed per sample: the last three
/// dimensions are computed and never drawn.
const OCTETS: usize = SOBOL_DIMS.div_ceil(8) as usize;
const _: () = assert!(8 * OCTETS as u32 <= sobol_burley::NUM_DIMENSIONS);

/// Mixes 64 bits into 64 well-distributed bits (SplitMix64 finaliser).
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The top 24 bits of `h` as a number in [0, 1) (each value exact in f32).
#[inline(always)]
pub fn unit_f32(h: u64) -> f32 {
    ((h >> 40) as f32) * (1.0 / (1u64 << 24) as f32)
}

/// A tiny deterministic generator for test data: SplitMix64 numbers in [0, 1).
#[cfg(test)]
pub(crate) struct TestRng(pub u64);

#[cfg(test)]
impl TestRng {
    pub(crate) fn f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(1);
        unit_f32(mix64(self.0))
    }
    pub(crate) fn vec3(&mut self) -> super::Vec3 {
        super::Vec3::new(self.f32(), self.f32(), self.f32())
    }
}

/// Hash of several integers, for seeding.
pub fn hash_seed(parts: &[u64]) -> u64 {
    parts
        .iter()
        .fold(0x5851_F42D_4C95_7F2Du64, |h, &p| mix64(h ^ mix64(p)))
}

#[derive(Clone, Debug)]
pub struct Sampler {
    seed: u64,
    dim: u32,
    /// The current sample's Sobol dimensions, all computed when it starts: paths in a closed
    /// scene use them all, and drawing from a full buffer needs no branch on when to refill
    /// (lanes at different depths made that branch unpredictable).
    buffer: [f32; 8 * OCTETS],
    /// SplitMix64 state of the current sample's dimensions past `SOBOL_DIMS`.
    tail: u64,
    /// `sobol_burley::sample_4d`'s work, split by what it depends on: per block of 2^16
    /// samples, the Owen scrambles of the index and of each dimension.
    block: u32,
    index_scramble: u32,
    dim_scramble: [u32x8; OCTETS],
}

impl Sampler {
    /// A sampler for one pixel (or any other stream key) of a render with seed `seed`.
    pub fn new(seed: u64, stream: u64) -> Sampler {
        let mut s = Sampler {
            seed: hash_seed(&[seed, stream]),
            dim: 0,
            buffer: [0.0; 8 * OCTETS],
            tail: 0,
            block: 0,
            index_scramble: 0,
            dim_scramble: [u32x8::ZERO; OCTETS],
        };
        // Ready for the first block, so that copies of a new sampler (`render::batch` starts
        // each sample of a pixel from one) need not redo it.
        s.scramble_block(0);
        s
    }

    /// Takes over `other`'s current sample: its numbers and how many have been drawn. Copies
    /// about half of what `clone_from` copies (the per-pixel scrambles stay behind, and are
    /// recomputed if this sampler ever starts a sample of its own): for a sampler that will
    /// only draw, as a path handed from a camera packet to a lane (`render::batch`).
    #[inline]
    pub fn take_sample_from(&mut self, other: &Sampler) {
        self.seed = other.seed;
        self.dim = other.dim;
        self.buffer = other.buffer;
        self.tail = other.tail;
        self.block = u32::MAX;
    }

    /// The Owen scrambles of block `block` of 2^16 samples: sobol_burley's sequences hold 2^16
    /// samples, and each further block is another independently scrambled sequence.
    fn scramble_block(&mut self, block: u32) {
        let seed = if block == 0 {
            self.seed
        } else {
            mix64(self.seed ^ block as u64)
        };
        let seed = (seed ^ (seed >> 32)) as u32;
        // As sample_4d (sobol_burley 0.5, lib.rs) computes them, for dimension 4 × set + k.
        self.index_scramble = parts::hash(seed ^ 0x79c6_8e4a);
        let lane = [0x912f_69ba, 0x174f_18ab, 0x691e_72ca, 0xb40c_c1b8];
        for (o, s) in self.dim_scramble.iter_mut().enumerate() {
            *s = u32x8::from(std::array::from_fn::<u32, 8, _>(|k| {
                let set = (8 * o + k) as u32 / 4;
                parts::hash(seed.wrapping_mul(0x9c8f_2d3b) ^ set ^ lane[k % 4])
            }));
        }
        self.block = block;
    }

    /// Starts sample number `index` of the stream (dimension 0).
    pub fn start_sample(&mut self, index: u32) {
        self.dim = 0;
        self.tail = mix64(self.seed ^ index as u64);
        if self.block != index >> 16 {
            self.scramble_block(index >> 16);
        }
        let shuffled_rev_index =
            parts::owen_scramble_rev((index & 0xFFFF).reverse_bits(), self.index_scramble);
        // What `sobol_burley::sample_4d(index, set, seed)` returns for each set, without
        // redoing its per-pixel and per-sample parts, eight dimensions at a time.
        let tables = sobol_tables();
        for (o, chunk) in self.buffer.chunks_exact_mut(8).enumerate() {
            let sobol = sobol_x8_rev(&tables[o], shuffled_rev_index);
            let x = reverse_bits_x8(owen_scramble_x8_rev(sobol, self.dim_scramble[o]));
            chunk.copy_from_slice(&to_f32_norm_x8(x).to_array());
        }
    }

    /// The next 1-D sample in [0, 1): a Sobol dimension or a SplitMix64 step.
    #[inline(always)]
    pub fn next_1d(&mut self) -> f32 {
        let d = self.dim;
        self.dim += 1;
        if d < SOBOL_DIMS {
            self.buffer[d as usize]
        } else {
            self.tail_1d()
        }
    }

    /// A dimension past `SOBOL_DIMS`. SplitMix64: `mix64` steps the state by the golden ratio
    /// and finalises it.
    #[inline(always)]
    fn tail_1d(&mut self) -> f32 {
        self.tail = self.tail.wrapping_add(0x9E37_79B9_7F4A_7C15);
        unit_f32(mix64(self.tail))
    }

    /// The next `N` dimensions, as `N` calls of [`Sampler::next_1d`] give them, with one branch
    /// where they are all Sobol or all SplitMix64.
    #[inline(always)]
    pub fn next_n<const N: usize>(&mut self) -> [f32; N] {
        let d = self.dim as usize;
        if d + N <= SOBOL_DIMS as usize {
            self.dim += N as u32;
            std::array::from_fn(|k| self.buffer[d + k])
        } else if d >= SOBOL_DIMS as usize {
            self.dim += N as u32;
            std::array::from_fn(|_| self.tail_1d())
        } else {
            std::array::from_fn(|_| self.next_1d())
        }
    }

    /// What [`Sampler::next_n`] would give, leaving this sampler as it is.
    #[inline]
    pub fn peek_n<const N: usize>(&self) -> [f32; N] {
        let d = self.dim as usize;
        if d + N <= SOBOL_DIMS as usize {
            std::array::from_fn(|k| self.buffer[d + k])
        } else {
            self.clone().next_n::<N>()
        }
    }

    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let a = self.next_1d();
        Vec2::new(a, self.next_1d())
    }
}

/// Eight dimensions' table: the 16-bit index's four nibbles times a nibble's 16 values.
type NibbleTable = [[u32x8; 16]; 4];

/// The tables of [`sobol_x8_rev`], one per eight dimensions, built on first use.
fn sobol_tables() -> &'static [NibbleTable; OCTETS] {
    static TABLES: OnceLock<Box<[NibbleTable; OCTETS]>> = OnceLock::new();
    TABLES.get_or_init(|| {
        Box::new(std::array::from_fn(|o| {
            std::array::from_fn(|k| {
                std::array::from_fn(|v| {
                    u32x8::from(std::array::from_fn::<u32, 8, _>(|d| {
                        parts::sobol_rev((v as u32) << (16 + 4 * k), (8 * o + d) as u32)
                    }))
                })
            })
        }))
    })
}

/// `parts::sobol_rev(index_rev, d)` for the eight dimensions d of table `t`
/// (`sobol_tables()[d / 8]`): a Sobol point is the XOR of the direction vectors of its
/// index's set bits (Joe & Kuo 2008), so it is the XOR of one precomputed value per nibble of
/// the index's top 16 bits, the only ones `sobol_rev` reads. Four loads in place of a loop
/// over the set bits whose unpredictable exit cost a branch miss per call (the loop was most
/// of the time spent computing Sobol points; `bench/README.md`, "Design measurements").
#[inline(always)]
fn sobol_x8_rev(t: &NibbleTable, index_rev: u32) -> u32x8 {
    let nibble = |k: usize| ((index_rev >> (16 + 4 * k)) & 15) as usize;
    t[0][nibble(0)] ^ t[1][nibble(1)] ^ t[2][nibble(2)] ^ t[3][nibble(3)]
}

/// `parts::owen_scramble_rev` on eight lanes (Burley 2020: a hash in which each bit
/// depends only on the bits below it in the reversed order, that is above it in the point).
#[inline(always)]
fn owen_scramble_x8_rev(n: u32x8, scramble: u32x8) -> u32x8 {
    let n = n ^ (n * u32x8::splat(0x3d20_adea));
    let n = (n + scramble) * ((scramble >> 16_u32) | u32x8::splat(1));
    let n = n ^ (n * u32x8::splat(0x0552_6c56));
    n ^ (n * u32x8::splat(0x53a2_2864))
}

/// `u32::reverse_bits` on eight lanes: swap halves of ever larger groups.
#[inline(always)]
fn reverse_bits_x8(n: u32x8) -> u32x8 {
    let swap =
        |n: u32x8, m: u32, s: u32| ((n >> s) & u32x8::splat(m)) | ((n & u32x8::splat(m)) << s);
    let n = swap(n, 0x5555_5555, 1);
    let n = swap(n, 0x3333_3333, 2);
    let n = swap(n, 0x0f0f_0f0f, 4);
    let n = swap(n, 0x00ff_00ff, 8);
    (n >> 16_u32) | (n << 16_u32)
}

/// `parts::u32_to_f32_norm` on eight lanes: the top 23 bits as the mantissa of a number in
/// [1, 2), minus 1.
#[inline(always)]
fn to_f32_norm_x8(n: u32x8) -> f32x8 {
    let bits = ((n >> 9_u32) | u32x8::splat(0x3f80_0000)).to_array();
    f32x8::from(bits.map(f32::from_bits)) - f32x8::ONE
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_stream_same_numbers_and_streams_differ() {
        let mut a = Sampler::new(7, 42);
        let mut b = Sampler::new(7, 42);
        let mut c = Sampler::new(7, 43);
        a.start_sample(3);
        b.start_sample(3);
        c.start_sample(3);
        let xa: Vec<f32> = (0..300).map(|_| a.next_1d()).collect();
        let xb: Vec<f32> = (0..300).map(|_| b.next_1d()).collect();
        let xc: Vec<f32> = (0..300).map(|_| c.next_1d()).collect();
        assert_eq!(xa, xb);
        assert_ne!(xa, xc);
        assert!(xa.iter().all(|&x| (0.0..1.0).contains(&x)));
    }

    #[test]
    fn sobol_dimensions_are_sobol_burleys_sample_4d() {
        // The split computation gives the crate's numbers, in the first block of 2^16 samples
        // and in a later one.
        let mut s = Sampler::new(9, 4);
        for index in [0u32, 1, 2, 77, 65535, 65536, 65537, 200_000, 3] {
            s.start_sample(index);
            let got: Vec<f32> = (0..SOBOL_DIMS).map(|_| s.next_1d()).collect();
            let block = (index >> 16) as u64;
            let seed = if block == 0 {
                s.seed
            } else {
                mix64(s.seed ^ block)
            };
            let scramble = (seed ^ (seed >> 32)) as u32;
            let want: Vec<f32> = (0..2 * OCTETS as u32)
                .flat_map(|k| sobol_burley::sample_4d(index & 0xFFFF, k, scramble))
                .take(SOBOL_DIMS as usize)
                .collect();
            assert_eq!(got, want, "sample {index}");
        }
    }

    #[test]
    fn sobol_tables_give_the_crates_points() {
        let mut rng = TestRng(5);
        for i in 0..2000u32 {
            let index_rev = if i < 16 {
                1u32 << (16 + i)
            } else {
                (rng.f32() * 4.0e9) as u32
            };
            for (o, t) in sobol_tables().iter().enumerate() {
                let want: [u32; 8] =
                    std::array::from_fn(|d| parts::sobol_rev(index_rev, (8 * o + d) as u32));
                assert_eq!(
                    sobol_x8_rev(t, index_rev).to_array(),
                    want,
                    "{index_rev:#x}"
                );
            }
        }
    }

    #[test]
    fn eight_lane_bit_operations_are_the_scalar_ones() {
        let mut rng = TestRng(11);
        for _ in 0..500 {
            let n: [u32; 8] = std::array::from_fn(|_| (rng.f32() * 4.0e9) as u32);
            let s: [u32; 8] = std::array::from_fn(|_| (rng.f32() * 4.0e9) as u32);
            let (nx, sx) = (u32x8::from(n), u32x8::from(s));
            let scrambled: [u32; 8] = std::array::from_fn(|k| parts::owen_scramble_rev(n[k], s[k]));
            assert_eq!(owen_scramble_x8_rev(nx, sx).to_array(), scrambled);
            assert_eq!(reverse_bits_x8(nx).to_array(), n.map(u32::reverse_bits));
            assert_eq!(to_f32_norm_x8(nx).to_array(), n.map(parts::u32_to_f32_norm));
        }
    }

    #[test]
    fn next_n_draws_what_next_1d_draws() {
        for start in 0..40 {
            let mut a = Sampler::new(3, 8);
            a.start_sample(5);
            let mut b = a.clone();
            for _ in 0..start {
                a.next_1d();
                b.next_1d();
            }
            let got: Vec<f32> = [a.next_n::<7>(), a.next_n::<7>()].concat();
            let want: Vec<f32> = (0..14).map(|_| b.next_1d()).collect();
            assert_eq!(got, want, "from dimension {start}");
        }
    }

    #[test]
    fn a_taken_sample_draws_and_restarts_as_the_original() {
        let mut a = Sampler::new(3, 8);
        a.start_sample(70_000);
        a.next_n::<5>();
        let mut b = Sampler::new(4, 9);
        b.start_sample(2);
        b.take_sample_from(&a);
        let (x, y): (Vec<f32>, Vec<f32>) = (0..60).map(|_| (a.next_1d(), b.next_1d())).unzip();
        assert_eq!(x, y);
        for index in [5, 70_001] {
            a.start_sample(index);
            b.start_sample(index);
            let (x, y): (Vec<f32>, Vec<f32>) = (0..60).map(|_| (a.next_1d(), b.next_1d())).unzip();
            assert_eq!(x, y, "sample {index}");
        }
    }

    #[test]
    fn one_dimension_is_stratified() {
        // 64 Sobol points fall one in each of 64 equal bins.
        let mut s = Sampler::new(1, 2);
        let mut bins = [0u32; 64];
        for i in 0..64 {
            s.start_sample(i);
            s.next_1d();
            let x = s.next_1d();
            bins[(x * 64.0) as usize] += 1;
        }
        assert!(bins.iter().all(|&b| b == 1), "{bins:?}");
    }
}
