//! NumPy-compatible random numbers: `np.random.Generator(PCG64(SeedSequence(seed)))`, bit for bit.
//!
//! Gymnasium seeds every environment with `np.random.default_rng(seed)`; to reproduce its episodes from a seed
//! we need the same stream of doubles. Three pieces are ported (see docs/environments.md, "Seeding"):
//!
//! 1. `SeedSequence`: turns the integer seed into 32-bit words (least significant first), hashes them
//!    into a 4-word entropy pool and expands the pool into as many output words as asked for
//!    (`generate_state`). This is NumPy's `numpy.random.bit_generator.SeedSequence` without spawn keys.
//! 2. The PCG64 bit generator ([`NumpyRng`]'s core): a 128-bit linear congruential generator with the standard
//!    128-bit PCG multiplier and the XSL-RR output function (XOR of the two halves, rotated by the top 6 bits).
//!    NumPy seeds it with four 64-bit words from `generate_state(4, uint64)`: words 0 and 1 are the high and low
//!    halves of the initial state, words 2 and 3 those of the stream selector (`pcg64_set_seed`).
//! 3. The `Generator` methods the environments use: [`NumpyRng::random`] (a double from the top 53 bits of one
//!    64-bit draw) and [`NumpyRng::uniform`] (`low + (high - low) * random()`).
//!
//! [`NumpyRng`] also implements [`rand::RngCore`], so the `rand`/`rand_distr` ecosystem can draw from it; its
//! `next_u32` reproduces NumPy's 32-bit buffering (the low half of a 64-bit draw first, the high half next).

use rand::RngCore;

/// Multiplier of PCG's 128-bit LCG (`PCG_DEFAULT_MULTIPLIER_128`), which NumPy's `PCG64` uses.
const PCG_MULTIPLIER_128: u128 =
    (2_549_297_995_355_413_924_u128 << 64) | 4_865_540_595_714_422_341_u128;

/// Size of SeedSequence's entropy pool in 32-bit words (`DEFAULT_POOL_SIZE`).
const POOL_SIZE: usize = 4;
// Hashing constants of NumPy's SeedSequence (after Melissa O'Neill's seed_seq_fe).
const INIT_A: u32 = 0x43b0_d7e5;
const MULT_A: u32 = 0x931e_8875;
const INIT_B: u32 = 0x8b51_f9dd;
const MULT_B: u32 = 0x58f3_8ded;
const MIX_MULT_L: u32 = 0xca01_f9dd;
const MIX_MULT_R: u32 = 0x4973_f715;
const XSHIFT: u32 = 16;

/// NumPy's `SeedSequence` for entropy given as an unsigned integer (no spawn key).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct SeedSequence {
    pool: [u32; POOL_SIZE],
}

impl SeedSequence {
    /// `SeedSequence(seed)` for an integer seed.
    pub fn new(seed: u64) -> Self {
        Self::from_u128(u128::from(seed))
    }

    /// `SeedSequence(entropy)` for an integer of up to 128 bits (NumPy's own unseeded entropy is 128 bits).
    pub(crate) fn from_u128(entropy: u128) -> Self {
        // `_int_to_uint32_array`: 32-bit words, least significant first; zero is one word [0].
        let mut words = [0u32; 4];
        let mut n_words = 0;
        let mut rest = entropy;
        loop {
            words[n_words] = rest as u32;
            n_words += 1;
            rest >>= 32;
            if rest == 0 {
                break;
            }
        }
        Self::from_words(&words[..n_words])
    }

    /// `SeedSequence` over an explicit array of 32-bit entropy words (`mix_entropy`).
    pub fn from_words(entropy: &[u32]) -> Self {
        let mut hash_const = INIT_A;
        let mut hashmix = |value: u32| -> u32 {
            let mut value = value ^ hash_const;
            hash_const = hash_const.wrapping_mul(MULT_A);
            value = value.wrapping_mul(hash_const);
            value ^ (value >> XSHIFT)
        };
        let mix = |x: u32, y: u32| -> u32 {
            let result = MIX_MULT_L
                .wrapping_mul(x)
                .wrapping_sub(MIX_MULT_R.wrapping_mul(y));
            result ^ (result >> XSHIFT)
        };

        let mut pool = [0u32; POOL_SIZE];
        // Fill the pool from the entropy (zeros beyond its end).
        for (i, slot) in pool.iter_mut().enumerate() {
            *slot = hashmix(entropy.get(i).copied().unwrap_or(0));
        }
        // Every pool word influences every other one.
        for i_src in 0..POOL_SIZE {
            for i_dst in 0..POOL_SIZE {
                if i_src != i_dst {
                    let hashed = hashmix(pool[i_src]);
                    pool[i_dst] = mix(pool[i_dst], hashed);
                }
            }
        }
        // Entropy words that did not fit into the pool are mixed into every pool word.
        for &word in entropy.iter().skip(POOL_SIZE) {
            for slot in pool.iter_mut() {
                let hashed = hashmix(word);
                *slot = mix(*slot, hashed);
            }
        }
        Self { pool }
    }

    /// `generate_state(n_words, uint32)`: expands the pool into `out.len()` 32-bit words.
    pub(crate) fn generate_state_u32(&self, out: &mut [u32]) {
        let mut hash_const = INIT_B;
        for (i, slot) in out.iter_mut().enumerate() {
            let mut value = self.pool[i % POOL_SIZE] ^ hash_const;
            hash_const = hash_const.wrapping_mul(MULT_B);
            value = value.wrapping_mul(hash_const);
            *slot = value ^ (value >> XSHIFT);
        }
    }

    /// `generate_state(n, uint64)`: the uint32 words viewed as little-endian uint64 pairs.
    pub(crate) fn generate_state_u64(&self, out: &mut [u64]) {
        let mut words = vec![0u32; out.len() * 2];
        self.generate_state_u32(&mut words);
        for (slot, pair) in out.iter_mut().zip(words.chunks_exact(2)) {
            *slot = u64::from(pair[0]) | (u64::from(pair[1]) << 32);
        }
    }
}

/// `np.random.Generator(PCG64(SeedSequence(seed)))`: NumPy's default generator, bit for bit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NumpyRng {
    state: u128,
    increment: u128,
    /// NumPy's 32-bit buffer: the high half of the last 64-bit draw, not yet handed out by `next_u32`.
    buffered_u32: Option<u32>,
}

impl NumpyRng {
    /// `np.random.default_rng(seed)` for an integer seed.
    pub fn new(seed: u64) -> Self {
        Self::from_seed_sequence(&SeedSequence::new(seed))
    }

    /// `np.random.default_rng()` without a seed: 128 bits of OS entropy through SeedSequence, as NumPy does.
    /// Only for Gymnasium's "first reset without a seed"; everything reproducible passes a seed.
    pub(crate) fn from_entropy() -> Self {
        let entropy: u128 = rand::random();
        Self::from_seed_sequence(&SeedSequence::from_u128(entropy))
    }

    /// `PCG64(seed_sequence)`: four 64-bit words become the initial state and the stream selector.
    pub(crate) fn from_seed_sequence(seed_sequence: &SeedSequence) -> Self {
        let mut words = [0u64; 4];
        seed_sequence.generate_state_u64(&mut words);
        let init_state = (u128::from(words[0]) << 64) | u128::from(words[1]);
        let init_sequence = (u128::from(words[2]) << 64) | u128::from(words[3]);
        Self::from_pcg_seed(init_state, init_sequence)
    }

    /// PCG's `srandom_r(initstate, initseq)`: odd increment from the sequence, two steps around adding the state.
    pub(crate) fn from_pcg_seed(init_state: u128, init_sequence: u128) -> Self {
        let mut rng = Self {
            state: 0,
            increment: (init_sequence << 1) | 1,
            buffered_u32: None,
        };
        rng.advance_lcg();
        rng.state = rng.state.wrapping_add(init_state);
        rng.advance_lcg();
        rng
    }

    /// The whole generator state as words (state, increment, 32-bit buffer), for snapshots.
    pub fn to_words(&self) -> [u64; 6] {
        let split = |x: u128| [(x >> 64) as u64, x as u64];
        let [s0, s1] = split(self.state);
        let [i0, i1] = split(self.increment);
        let (has, buf) = match self.buffered_u32 {
            Some(b) => (1, u64::from(b)),
            None => (0, 0),
        };
        [s0, s1, i0, i1, has, buf]
    }

    /// The generator [`NumpyRng::to_words`] described.
    pub fn from_words(w: [u64; 6]) -> Self {
        let join = |hi: u64, lo: u64| (u128::from(hi) << 64) | u128::from(lo);
        Self {
            state: join(w[0], w[1]),
            increment: join(w[2], w[3]),
            buffered_u32: (w[4] != 0).then_some(w[5] as u32),
        }
    }

    /// The 128-bit LCG state and increment (as NumPy's `bit_generator.state` reports them).
    pub fn pcg_state(&self) -> (u128, u128) {
        (self.state, self.increment)
    }

    #[inline]
    fn advance_lcg(&mut self) {
        self.state = self
            .state
            .wrapping_mul(PCG_MULTIPLIER_128)
            .wrapping_add(self.increment);
    }

    /// One raw 64-bit draw (`bit_generator.random_raw()`): step, then XSL-RR output of the new state.
    #[inline]
    pub(crate) fn next_raw_u64(&mut self) -> u64 {
        self.advance_lcg();
        let xored = ((self.state >> 64) as u64) ^ (self.state as u64);
        let rotation = (self.state >> 122) as u32;
        xored.rotate_right(rotation)
    }

    /// `Generator.random()`: a double in [0, 1) from the top 53 bits of one 64-bit draw.
    #[inline]
    pub fn random(&mut self) -> f64 {
        (self.next_raw_u64() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }

    /// `Generator.uniform(low, high)`: `low + (high - low) * random()`, in NumPy's operation order.
    #[inline]
    pub fn uniform(&mut self, low: f64, high: f64) -> f64 {
        let range = high - low;
        low + range * self.random()
    }

    /// `Generator.uniform(low, high, size=out.len())`: the draws in order.
    pub(crate) fn uniform_fill(&mut self, low: f64, high: f64, out: &mut [f64]) {
        for slot in out {
            *slot = self.uniform(low, high);
        }
    }
}

impl RngCore for NumpyRng {
    /// NumPy's `next_uint32`: the low half of a fresh 64-bit draw, keeping the high half for the next call.
    fn next_u32(&mut self) -> u32 {
        if let Some(high) = self.buffered_u32.take() {
            return high;
        }
        let raw = self.next_raw_u64();
        self.buffered_u32 = Some((raw >> 32) as u32);
        raw as u32
    }

    /// NumPy's `next_uint64` (ignores, and keeps, any buffered 32-bit half, as NumPy does).
    fn next_u64(&mut self) -> u64 {
        self.next_raw_u64()
    }

    fn fill_bytes(&mut self, dest: &mut [u8]) {
        for chunk in dest.chunks_mut(8) {
            let bytes = self.next_raw_u64().to_le_bytes();
            chunk.copy_from_slice(&bytes[..chunk.len()]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Reference values recorded with NumPy 2.4.6:
    //   import numpy as np
    //   for s in [0, 42, 2**32+5, 2**64-1]:
    //       print([hex(x) for x in np.random.SeedSequence(s).generate_state(4, np.uint64)])
    #[test]
    fn seed_sequence_matches_numpy_generate_state() {
        let cases: [(u64, [u64; 4]); 4] = [
            (
                0,
                [
                    0xdb2cd7e7b0f478be,
                    0xabf4641a2c71ba49,
                    0x20c6ed6d9d7b8d41,
                    0x2c4099de223c39d4,
                ],
            ),
            (
                42,
                [
                    0x9f1e2e6dcd540ab7,
                    0xd57873dc79fb94b6,
                    0x7d282a1b64d420b7,
                    0x336579714692d5ff,
                ],
            ),
            (
                (1 << 32) + 5,
                [
                    0xf9c15bd6e249d9ac,
                    0xb2021b4036320ed7,
                    0x9388b47fe6dcf739,
                    0x5eeba8d9ad6439e1,
                ],
            ),
            (
                u64::MAX,
                [
                    0xaebca151928cad0d,
                    0x119c30448638dc7a,
                    0x1bbb155659e642a7,
                    0xa76b11e3e8c4a8f6,
                ],
            ),
        ];
        for (seed, expected) in cases {
            let mut words = [0u64; 4];
            SeedSequence::new(seed).generate_state_u64(&mut words);
            assert_eq!(words, expected, "seed {seed}");
        }
    }

    // Python (NumPy 2.4.6):
    //   [hex(x) for x in np.random.SeedSequence(2**128-3).generate_state(2, np.uint64)]
    //   [hex(x) for x in np.random.SeedSequence([1,2,3,4,5,6]).generate_state(2, np.uint64)]
    #[test]
    fn seed_sequence_wide_entropy_matches_numpy() {
        let mut words = [0u64; 2];
        SeedSequence::from_u128(u128::MAX - 2).generate_state_u64(&mut words);
        assert_eq!(words, [0xe8b7eee240003a81, 0x026cf149880b68ca]);
        // More entropy words than the pool holds: the extra words are mixed in afterwards.
        SeedSequence::from_words(&[1, 2, 3, 4, 5, 6]).generate_state_u64(&mut words);
        assert_eq!(words, [0xebcd001d1d1bca21, 0xcfea83a4b202608b]);
    }

    // Python (NumPy 2.4.6):
    //   bg = np.random.PCG64(0); print(bg.state['state'])
    #[test]
    fn pcg64_seeded_state_matches_numpy() {
        let rng = NumpyRng::new(0);
        let (state, increment) = rng.pcg_state();
        assert_eq!(state, 35399562948360463058890781895381311971);
        assert_eq!(increment, 87136372517582989555478159403783844777);
    }

    // Python: [hex(x) for x in np.random.PCG64(s).random_raw(3)] for s in [0, 42, 2**32+5, 2**64-1]
    #[test]
    fn raw_draws_match_numpy() {
        let cases: [(u64, [u64; 3]); 4] = [
            (
                0,
                [0xa30febcfd9c2825f, 0x4510bdf882d9d721, 0x0a7d3da94ecde8b8],
            ),
            (
                42,
                [0xc621fbcd16d92688, 0x705a5661a791ffc1, 0xdbcd12c26eda1624],
            ),
            (
                (1 << 32) + 5,
                [0xc6323ec321deb8d1, 0x78814821c73a0583, 0xb22536d8e0ec17c0],
            ),
            (
                u64::MAX,
                [0xae163a7a8c47568f, 0xd86659f5f3382359, 0x01e52b195bc2d24a],
            ),
        ];
        for (seed, expected) in cases {
            let mut rng = NumpyRng::new(seed);
            let drawn = [rng.next_raw_u64(), rng.next_raw_u64(), rng.next_raw_u64()];
            assert_eq!(drawn, expected, "seed {seed}");
        }
    }

    // Python: np.random.Generator(np.random.PCG64(s)).random(2)
    //         np.random.Generator(np.random.PCG64(s)).uniform(-0.05, 0.05, size=4)
    #[test]
    fn random_and_uniform_match_numpy() {
        let cases: [(u64, [f64; 2], [f64; 4]); 3] = [
            (
                0,
                [0.6369616873214543, 0.2697867137638703],
                [
                    0.013696168732145436,
                    -0.02302132862361297,
                    -0.045902647606380534,
                    -0.04834723644714709,
                ],
            ),
            (
                42,
                [0.7739560485559633, 0.4388784397520523],
                [
                    0.027395604855596334,
                    -0.006112156024794771,
                    0.03585979199113824,
                    0.019736802905936393,
                ],
            ),
            (
                u64::MAX,
                [0.6800266789616931, 0.8453117585624743],
                [
                    0.018002667896169305,
                    0.03453117585624743,
                    -0.049259691840074,
                    0.039456812643914735,
                ],
            ),
        ];
        for (seed, expected_random, expected_uniform) in cases {
            let mut rng = NumpyRng::new(seed);
            assert_eq!([rng.random(), rng.random()], expected_random, "seed {seed}");
            let mut rng = NumpyRng::new(seed);
            let mut drawn = [0.0; 4];
            rng.uniform_fill(-0.05, 0.05, &mut drawn);
            assert_eq!(drawn, expected_uniform, "seed {seed}");
        }
        // Python: g = np.random.Generator(np.random.PCG64(7)); g.uniform(-0.6, -0.4), g.uniform(0.0, 200.0)
        let mut rng = NumpyRng::new(7);
        assert_eq!(rng.uniform(-0.6, -0.4), -0.4749809066790666);
        assert_eq!(rng.uniform(0.0, 200.0), 179.4427601939151);
    }

    // Python: bg = np.random.PCG64(0); c = bg.ctypes
    //         [hex(c.next_uint32(c.state)) for _ in range(3)], hex(c.next_uint64(c.state))
    #[test]
    fn next_u32_buffers_like_numpy() {
        let mut rng = NumpyRng::new(0);
        let drawn = [rng.next_u32(), rng.next_u32(), rng.next_u32()];
        assert_eq!(drawn, [0xd9c2825f, 0xa30febcf, 0x82d9d721]);
        assert_eq!(rng.next_u64(), 0x0a7d3da94ecde8b8);
    }

    #[test]
    fn entropy_seeded_generators_differ() {
        assert_ne!(NumpyRng::from_entropy(), NumpyRng::from_entropy());
    }
}
