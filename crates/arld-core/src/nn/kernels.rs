//! The matrix product of the network, with one fixed floating-point order on every instruction set.
//!
//! [`product`] computes `dst[r][c] = init[c] + Σ_k a(r, k) · b[k][c]` as one chain of fused multiply-adds
//! per output element, `acc = fma(a(r, k), b[k][c], acc)` for `k = 0, 1, …` in order, starting from the
//! bias (or zero). Vectors only ever run across output columns `c`, never along `k`, so the lane width
//! changes how many elements are computed at once but not how any one of them is computed: the scalar,
//! AVX2 and AVX-512 paths ([`Lanes`]) give the same bytes, and a row's result does not depend on the
//! other rows of the batch (a single-state forward equals the same row of a batched one).
//!
//! `b` is always row-major with contiguous columns; `a` is any strided view (so `Xᵀ · dY` reads `X` in
//! place). A product with `bᵀ` (the input gradient `dY · Wᵀ`) first writes `Wᵀ` with [`transpose`] (8 x 8
//! blocks in vector registers). A product with fewer columns than a vector whose `a` has adjacent rows (`Xᵀ`
//! for the weight gradient of a layer with 1-7 outputs) runs its vectors across rows instead of columns:
//! still one FMA chain per output, in the same order.
//!
//! Outputs are computed in register blocks of `R` rows by `C` vectors whose accumulators stay in
//! registers over the whole `k` loop; on the vector levels the leftover columns (fewer than a vector) run in
//! narrower vectors (8 lanes, then 4 lanes, the last 1-3 columns masked), on the scalar level one lane at a
//! time with `f32::mul_add`, which rounds exactly like a vector lane.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;
use std::cell::Cell;

thread_local! {
    /// Floating-point operations of the products run on this thread (see [`product_flops`]).
    static PRODUCT_FLOPS: Cell<u64> = const { Cell::new(0) };
}

/// The floating-point operations of every matrix product ([`product`]) this thread has run: two per
/// multiply-add, `2 m k n` for an `m x k` by `k x n` product. A benchmark reads it before and after a piece
/// of work to count that work's arithmetic (the per-step account of `benches/box_update.rs`).
pub fn product_flops() -> u64 {
    PRODUCT_FLOPS.with(Cell::get)
}

/// A vector of `WIDTH` f32 lanes and the four operations the kernel needs.
///
/// # Safety
/// The implementations for vector types must only be called inside functions compiled with the matching
/// target features, and `load`/`store` need `WIDTH` readable/writable floats at the pointer.
pub(crate) trait Lanes {
    const WIDTH: usize;
    /// Vector registers of the instruction set, which bound a register block's size in [`product`].
    const REGISTERS: usize;
    type V: Copy;
    unsafe fn splat(x: f32) -> Self::V;
    unsafe fn load(p: *const f32) -> Self::V;
    unsafe fn store(p: *mut f32, v: Self::V);
    /// `a * b + c` with one rounding.
    unsafe fn fma(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `g` in the lanes where `a > 0`, +0 elsewhere (ReLU's backward pass), by a bit mask.
    unsafe fn keep_where_positive(g: Self::V, a: Self::V) -> Self::V;
    /// The first `lanes` floats at `p` (1 to `WIDTH`), the other lanes zero; only those floats are read.
    #[inline(always)]
    unsafe fn load_first(p: *const f32, lanes: usize) -> Self::V {
        debug_assert_eq!(lanes, Self::WIDTH);
        // SAFETY: forwarded; a level without masked loads is only asked for whole vectors.
        unsafe { Self::load(p) }
    }
    /// Stores the first `lanes` lanes of `v` at `p`; only those floats are written.
    #[inline(always)]
    unsafe fn store_first(p: *mut f32, v: Self::V, lanes: usize) {
        debug_assert_eq!(lanes, Self::WIDTH);
        // SAFETY: forwarded; a level without masked stores is only asked for whole vectors.
        unsafe { Self::store(p, v) }
    }
    /// Whether [`Self::transpose8`] moves whole 8 x 8 blocks in vector registers (else [`transpose`] moves
    /// every element on its own).
    const TRANSPOSES_BLOCKS: bool = false;
    /// Writes the transpose of the 8 x 8 block at `src` (rows `src_stride` floats apart) to `dst` (rows
    /// `dst_stride` apart): `dst[c][r] = src[r][c]`.
    #[inline(always)]
    unsafe fn transpose8(src: *const f32, src_stride: usize, dst: *mut f32, dst_stride: usize) {
        for r in 0..8 {
            for c in 0..8 {
                // SAFETY: the caller guarantees both 8 x 8 blocks lie inside their slices.
                unsafe { *dst.add(c * dst_stride + r) = *src.add(r * src_stride + c) };
            }
        }
    }
}

/// One lane at a time.
pub(crate) struct Scalar;

impl Lanes for Scalar {
    const WIDTH: usize = 1;
    const REGISTERS: usize = 16;
    type V = f32;
    #[inline(always)]
    unsafe fn splat(x: f32) -> f32 {
        x
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> f32 {
        // SAFETY: the caller guarantees one readable float.
        unsafe { *p }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: f32) {
        // SAFETY: the caller guarantees one writable float.
        unsafe { *p = v }
    }
    #[inline(always)]
    unsafe fn fma(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
    #[inline(always)]
    unsafe fn keep_where_positive(g: f32, a: f32) -> f32 {
        if a > 0.0 { g } else { 0.0 }
    }
}

/// 8 lanes (AVX2 + FMA).
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    const WIDTH: usize = 8;
    const REGISTERS: usize = 16;
    type V = __m256;
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m256 {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m256 {
        unsafe { _mm256_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m256) {
        unsafe { _mm256_storeu_ps(p, v) }
    }
    #[inline(always)]
    unsafe fn fma(a: __m256, b: __m256, c: __m256) -> __m256 {
        unsafe { _mm256_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    unsafe fn keep_where_positive(g: __m256, a: __m256) -> __m256 {
        unsafe { _mm256_and_ps(g, _mm256_cmp_ps::<_CMP_GT_OQ>(a, _mm256_setzero_ps())) }
    }
    #[inline(always)]
    unsafe fn load_first(p: *const f32, lanes: usize) -> __m256 {
        // SAFETY: the caller guarantees `lanes` readable floats; the masked-out lanes are not accessed.
        unsafe { _mm256_maskload_ps(p, avx2_mask(lanes)) }
    }
    #[inline(always)]
    unsafe fn store_first(p: *mut f32, v: __m256, lanes: usize) {
        // SAFETY: the caller guarantees `lanes` writable floats; only those are written.
        unsafe {
            if lanes == 8 {
                _mm256_storeu_ps(p, v);
            } else if lanes > 4 {
                _mm_storeu_ps(p, _mm256_castps256_ps128(v));
                store_first_of_4(p.add(4), _mm256_extractf128_ps::<1>(v), lanes - 4);
            } else {
                store_first_of_4(p, _mm256_castps256_ps128(v), lanes);
            }
        }
    }
    const TRANSPOSES_BLOCKS: bool = true;
    #[inline(always)]
    unsafe fn transpose8(src: *const f32, src_stride: usize, dst: *mut f32, dst_stride: usize) {
        // SAFETY: the caller guarantees both 8 x 8 blocks lie inside their slices.
        unsafe { avx_transpose8(src, src_stride, dst, dst_stride) }
    }
}

/// The 8 x 8 transpose of [`Lanes::transpose8`] in AVX registers: pairs of rows interleaved, then pairs of
/// pairs, then the 128-bit halves exchanged (24 shuffles for 64 floats instead of 64 single stores).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn avx_transpose8(src: *const f32, src_stride: usize, dst: *mut f32, dst_stride: usize) {
    // SAFETY: the caller guarantees 8 rows of 8 readable floats at `src` and writable ones at `dst`.
    unsafe {
        let r: [__m256; 8] = std::array::from_fn(|i| _mm256_loadu_ps(src.add(i * src_stride)));
        // t[2i] = (r[2i][0], r[2i+1][0], r[2i][1], r[2i+1][1] | the same for columns 4 and 5), t[2i+1]: 2, 3 | 6, 7.
        let t: [__m256; 8] = std::array::from_fn(|i| {
            let (a, b) = (r[i / 2 * 2], r[i / 2 * 2 + 1]);
            if i % 2 == 0 {
                _mm256_unpacklo_ps(a, b)
            } else {
                _mm256_unpackhi_ps(a, b)
            }
        });
        // s[4h + c]: rows 4h..4h+4 of column c (low half) and of column c + 4 (high half).
        let s: [__m256; 8] = std::array::from_fn(|i| {
            let (h, c) = (i / 4, i % 4);
            let (a, b) = (t[4 * h + c / 2], t[4 * h + c / 2 + 2]);
            if c % 2 == 0 {
                _mm256_shuffle_ps::<0x44>(a, b)
            } else {
                _mm256_shuffle_ps::<0xEE>(a, b)
            }
        });
        for c in 0..4 {
            _mm256_storeu_ps(
                dst.add(c * dst_stride),
                _mm256_permute2f128_ps::<0x20>(s[c], s[4 + c]),
            );
            _mm256_storeu_ps(
                dst.add((c + 4) * dst_stride),
                _mm256_permute2f128_ps::<0x31>(s[c], s[4 + c]),
            );
        }
    }
}

/// Stores the first `lanes` (1 to 4) lanes of `v` at `p` with plain stores (4, 2 and 1 floats wide): AMD
/// CPUs run the masked store `vmaskmovps` in microcode, tens of cycles for each output row of a narrow layer.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn store_first_of_4(p: *mut f32, v: __m128, lanes: usize) {
    debug_assert!((1..=4).contains(&lanes));
    // SAFETY: the caller guarantees `lanes` writable floats at `p`; each store below writes inside them.
    unsafe {
        match lanes {
            4 => _mm_storeu_ps(p, v),
            3 => {
                _mm_storel_epi64(p.cast(), _mm_castps_si128(v));
                _mm_store_ss(p.add(2), _mm_movehl_ps(v, v));
            }
            2 => _mm_storel_epi64(p.cast(), _mm_castps_si128(v)),
            _ => _mm_store_ss(p, v),
        }
    }
}

/// The AVX2 mask of the first `lanes` (1 to 8) lanes.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn avx2_mask(lanes: usize) -> __m256i {
    const ONES_THEN_ZEROS: [i32; 16] = [-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0];
    debug_assert!((1..=8).contains(&lanes));
    // SAFETY: `8 - lanes` is in 0..8, so 8 ints from there lie inside the table.
    unsafe { _mm256_loadu_si256(ONES_THEN_ZEROS.as_ptr().add(8 - lanes).cast()) }
}

/// 16 lanes (AVX-512F).
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx512;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx512 {
    const WIDTH: usize = 16;
    const REGISTERS: usize = 32;
    type V = __m512;
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m512 {
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m512 {
        unsafe { _mm512_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m512) {
        unsafe { _mm512_storeu_ps(p, v) }
    }
    #[inline(always)]
    unsafe fn fma(a: __m512, b: __m512, c: __m512) -> __m512 {
        unsafe { _mm512_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    unsafe fn keep_where_positive(g: __m512, a: __m512) -> __m512 {
        unsafe { _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, _mm512_setzero_ps()), g) }
    }
    const TRANSPOSES_BLOCKS: bool = true;
    #[inline(always)]
    unsafe fn transpose8(src: *const f32, src_stride: usize, dst: *mut f32, dst_stride: usize) {
        // SAFETY: the caller guarantees both 8 x 8 blocks lie inside their slices; the AVX-512 level implies
        // AVX (`SimdLevel::detected`).
        unsafe { avx_transpose8(src, src_stride, dst, dst_stride) }
    }
}

/// The first `N` (1 to 4) lanes of a 4-lane vector (FMA; masked loads from AVX and plain 4-, 2- and 1-float
/// stores touch only those `N` floats): the column rest below 8 columns of the AVX-512 level, so no output runs
/// lane by lane there.
/// The unused lanes compute on zeros and are never stored.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Fma4<const N: usize>;

#[cfg(target_arch = "x86_64")]
impl<const N: usize> Fma4<N> {
    #[inline(always)]
    unsafe fn mask() -> __m128i {
        unsafe {
            _mm_setr_epi32(
                if N > 0 { -1 } else { 0 },
                if N > 1 { -1 } else { 0 },
                if N > 2 { -1 } else { 0 },
                if N > 3 { -1 } else { 0 },
            )
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl<const N: usize> Lanes for Fma4<N> {
    const WIDTH: usize = N;
    const REGISTERS: usize = 16;
    type V = __m128;
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m128 {
        unsafe { _mm_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m128 {
        // SAFETY: the caller guarantees `N` readable floats; the masked-out lanes are not accessed.
        unsafe { _mm_maskload_ps(p, Self::mask()) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m128) {
        // SAFETY: the caller guarantees `N` writable floats; only those are written.
        unsafe { store_first_of_4(p, v, N) }
    }
    #[inline(always)]
    unsafe fn fma(a: __m128, b: __m128, c: __m128) -> __m128 {
        unsafe { _mm_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    unsafe fn keep_where_positive(g: __m128, a: __m128) -> __m128 {
        unsafe { _mm_and_ps(g, _mm_cmpgt_ps(a, _mm_setzero_ps())) }
    }
}

/// A strided `rows x cols` left operand: element `(r, k)` at `r * row_stride + k * col_stride`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Strided<'a> {
    pub data: &'a [f32],
    pub rows: usize,
    pub cols: usize,
    pub row_stride: usize,
    pub col_stride: usize,
}

impl<'a> Strided<'a> {
    /// A dense row-major matrix.
    pub fn row_major(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            row_stride: cols,
            col_stride: 1,
        }
    }

    /// The transpose of the row-major `rows x cols` matrix in `data` (a `cols x rows` view).
    pub fn transposed(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows: cols,
            cols: rows,
            row_stride: 1,
            col_stride: cols,
        }
    }
}

/// `dst[r][c] = init[c] + Σ_k a(r, k) · b[k][c]` (see the module docs for the order), with `dst` row-major
/// `a.rows x n`, `b` row-major `a.cols x n`, and `init` the bias row (length `n`) or `None` for zero.
///
/// # Panics
/// If a slice is shorter than its shape needs (programming errors, never input errors).
#[inline(always)]
pub(crate) fn product<S: Lanes>(dst: &mut [f32], a: Strided, b: &[f32], init: Option<&[f32]>) {
    let (m, k) = (a.rows, a.cols);
    let n = dst.len().checked_div(m).unwrap_or(0);
    assert_eq!(dst.len(), m * n, "product: destination is not rows x n");
    assert!(b.len() >= k * n, "product: right operand too short");
    if let Some(bias) = init {
        assert_eq!(bias.len(), n, "product: bias length is not n");
    }
    if m == 0 || n == 0 {
        return;
    }
    PRODUCT_FLOPS.with(|flops| flops.set(flops.get() + 2 * (m * k * n) as u64));
    assert!(
        (m - 1) * a.row_stride + k.saturating_sub(1) * a.col_stride < a.data.len() || k == 0,
        "product: left view exceeds its slice"
    );
    let mut p = Operands {
        dst: dst.as_mut_ptr(),
        n,
        a: a.data.as_ptr(),
        a_rs: a.row_stride,
        a_cs: a.col_stride,
        b: b.as_ptr(),
        init: init.map(|bias| bias.as_ptr()),
        k,
    };
    let mut m = m;
    // SAFETY: every block below stays inside rows 0..m and columns 0..n, which the asserts above showed
    // to lie inside the slices; `dst` is borrowed mutably, so it aliases nothing.
    unsafe {
        // Fewer columns than a vector, and a left operand whose rows are adjacent (`Xᵀ` of a layer's input
        // for a gradient of a 1-7 column layer: a critic's value, the actions of a Q-network): the vectors run
        // across rows instead, so no lane idles. The rows left over go through the column blocks below.
        // Blocks of `RV` vectors of rows by up to 4 columns: at least 8 accumulators (the FMA latency times
        // two pipes) where the rows allow, within the register file (16 ymm registers: 4 x 2 for one or two
        // columns, else 2 x 4).
        if S::WIDTH >= 8 && p.a_rs == 1 && n < S::WIDTH {
            let done = match n {
                1 => row_vector_blocks::<S, 8>(&p, 0, m),
                2 => row_vector_blocks::<S, 4>(&p, 0, m),
                _ if S::REGISTERS >= 32 => row_vector_blocks::<S, 4>(&p, 0, m),
                _ => 0,
            };
            let done = row_vector_blocks::<S, 2>(&p, done, m);
            let done = row_vector_blocks::<S, 1>(&p, done, m);
            p.dst = p.dst.add(done * n);
            p.a = p.a.add(done);
            m -= done;
            if m == 0 {
                return;
            }
        }
        let full = n / S::WIDTH * S::WIDTH;
        // Block shape: R rows x C vectors of accumulators, plus C loaded vectors and one broadcast, must fit
        // the register file, with more accumulators than the FMA latency times the two pipes (8) so that the
        // pipes never wait: 6 x 4 (29 registers) with 32 of them, 6 x 2 (15) with 16. One or two rows (a
        // single-state forward) run in blocks of 4 vectors, which always fit.
        let mut col = if S::REGISTERS >= 32 {
            column_blocks::<S, 6, 4>(&p, m, full)
        } else if m >= 3 {
            column_blocks::<S, 6, 2>(&p, m, full)
        } else {
            column_blocks::<S, 4, 4>(&p, m, full)
        };
        // AVX2's rest (under 16 columns, or 32 for fewer than 4 rows): 9-15 columns as blocks of two vectors
        // whose second is masked, 1-8 as one (masked) vector over 12 rows at a time, so that 12 accumulators
        // hide the FMA latency as in the full blocks.
        #[cfg(target_arch = "x86_64")]
        if S::WIDTH == Avx2::WIDTH {
            while col + 2 * S::WIDTH <= n {
                rows_blocked::<S, 6, 2, false>(&p, m, col, S::WIDTH);
                col += 2 * S::WIDTH;
            }
            match n - col {
                0 => {}
                rest @ 1..=8 => rows_blocked::<S, 12, 1, true>(&p, m, col, rest),
                rest => rows_blocked::<S, 6, 2, true>(&p, m, col, rest - S::WIDTH),
            }
            col = n;
        }
        while col + S::WIDTH <= full {
            rows_blocked::<S, 8, 1, false>(&p, m, col, S::WIDTH);
            col += S::WIDTH;
        }
        // An 8-column rest of a 16-lane level in AVX2 vectors (the 10 heads' 40 columns), not lane by lane,
        // 8 rows at a time as the AVX2 level's rest.
        #[cfg(target_arch = "x86_64")]
        if S::WIDTH > Avx2::WIDTH && col + Avx2::WIDTH <= n {
            // The AVX-512 level is only chosen on CPUs that also have AVX2 and FMA (`SimdLevel::detected`).
            rows_blocked::<Avx2, 8, 1, false>(&p, m, col, Avx2::WIDTH);
            col += Avx2::WIDTH;
        }
        // A rest under 8 columns of the AVX-512 level (the tasks' 2-4 actions, the heads' 4- and 6-column
        // rests) in 4-lane FMA vectors, masked for the last 1-3 columns; 8 rows at a time, so that 8
        // independent accumulators hide the FMA latency (4 rows left the output layer latency-bound).
        #[cfg(target_arch = "x86_64")]
        if S::WIDTH > Avx2::WIDTH {
            if col + 4 <= n {
                rows_blocked::<Fma4<4>, 8, 1, false>(&p, m, col, 4);
                col += 4;
            }
            match n - col {
                1 => rows_blocked::<Fma4<1>, 8, 1, false>(&p, m, col, 1),
                2 => rows_blocked::<Fma4<2>, 8, 1, false>(&p, m, col, 2),
                3 => rows_blocked::<Fma4<3>, 8, 1, false>(&p, m, col, 3),
                _ => {}
            }
            col = n;
        }
        while col < n {
            rows_blocked::<Scalar, 4, 1, false>(&p, m, col, 1);
            col += 1;
        }
    }
}

/// Raw operands of [`product`], checked by it.
struct Operands {
    dst: *mut f32,
    n: usize,
    a: *const f32,
    a_rs: usize,
    a_cs: usize,
    b: *const f32,
    init: Option<*const f32>,
    k: usize,
}

/// Blocks of `R` rows by `C` vectors from column 0 while they fit in `full`; returns the first column left.
#[inline(always)]
unsafe fn column_blocks<S: Lanes, const R: usize, const C: usize>(
    p: &Operands,
    m: usize,
    full: usize,
) -> usize {
    let mut col = 0;
    while col + C * S::WIDTH <= full {
        // SAFETY: forwarded from `product`.
        unsafe { rows_blocked::<S, R, C, false>(p, m, col, S::WIDTH) };
        col += C * S::WIDTH;
    }
    col
}

/// Rows `from..` of the product in blocks of `RV` vectors of rows (a left operand with `a_rs == 1`), every
/// column, while whole blocks fit in `m` rows; returns the first row left.
#[inline(always)]
unsafe fn row_vector_blocks<S: Lanes, const RV: usize>(
    p: &Operands,
    from: usize,
    m: usize,
) -> usize {
    let mut row = from;
    while row + RV * S::WIDTH <= m {
        let mut col = 0;
        while col < p.n {
            // SAFETY: forwarded from `product`.
            unsafe {
                match p.n - col {
                    1 => row_vector_block::<S, RV, 1>(p, row, col),
                    2 => row_vector_block::<S, RV, 2>(p, row, col),
                    3 => row_vector_block::<S, RV, 3>(p, row, col),
                    _ => row_vector_block::<S, RV, 4>(p, row, col),
                }
            }
            col += 4;
        }
        row += RV * S::WIDTH;
    }
    row
}

/// Rows `row..row + RV * WIDTH`, columns `col..col + CG` with vectors across rows: `CG x RV` accumulators over
/// the whole `k` loop, each lane the FMA chain of one output as in [`block`]; stored lane by lane.
#[inline(always)]
unsafe fn row_vector_block<S: Lanes, const RV: usize, const CG: usize>(
    p: &Operands,
    row: usize,
    col: usize,
) {
    // SAFETY: forwarded from `product` (every pointer offset is inside the checked shapes; `a_rs == 1`, so
    // rows `row..row + RV * WIDTH` of column `k` of the left operand are adjacent).
    unsafe {
        let mut acc = [[S::splat(0.0); RV]; CG];
        if let Some(bias) = p.init {
            for (c, acc) in acc.iter_mut().enumerate() {
                *acc = [S::splat(*bias.add(col + c)); RV];
            }
        }
        let mut a_ptr = p.a.add(row);
        let mut b_ptr = p.b.add(col);
        for _ in 0..p.k {
            let av: [S::V; RV] = std::array::from_fn(|v| S::load(a_ptr.add(v * S::WIDTH)));
            for (c, acc) in acc.iter_mut().enumerate() {
                let bv = S::splat(*b_ptr.add(c));
                for (acc, &av) in acc.iter_mut().zip(&av) {
                    *acc = S::fma(av, bv, *acc);
                }
            }
            a_ptr = a_ptr.add(p.a_cs);
            b_ptr = b_ptr.add(p.n);
        }
        let mut lanes = [0.0f32; 16];
        debug_assert!(S::WIDTH <= lanes.len());
        for (c, acc) in acc.iter().enumerate() {
            for (v, &acc) in acc.iter().enumerate() {
                S::store(lanes.as_mut_ptr(), acc);
                let out = p.dst.add((row + v * S::WIDTH) * p.n + col + c);
                for (lane, &value) in lanes[..S::WIDTH].iter().enumerate() {
                    *out.add(lane * p.n) = value;
                }
            }
        }
    }
}

/// Columns `col..` of all `m` rows in blocks of `C` vectors, `R` rows at a time; the rows left (fewer than `R`)
/// in one block of 8, 5 or 4 rows where they fit and then one of the 1-3 left, so that a batch of 32 rows in
/// blocks of 6 keeps 2 rows together rather than running them one at a time (one row's `C` accumulators
/// cannot hide the FMA latency). `MASKED`: the last vector holds only its first `lanes` columns.
#[inline(always)]
unsafe fn rows_blocked<S: Lanes, const R: usize, const C: usize, const MASKED: bool>(
    p: &Operands,
    m: usize,
    col: usize,
    lanes: usize,
) {
    let mut row = 0;
    // SAFETY: forwarded from `product`.
    unsafe {
        while row + R <= m {
            block::<S, R, C, MASKED>(p, row, col, lanes);
            row += R;
        }
        if R > 8 && row + 8 <= m {
            block::<S, 8, C, MASKED>(p, row, col, lanes);
            row += 8;
        }
        if R > 5 && row + 5 <= m {
            block::<S, 5, C, MASKED>(p, row, col, lanes);
            row += 5;
        }
        if R > 4 && row + 4 <= m {
            block::<S, 4, C, MASKED>(p, row, col, lanes);
            row += 4;
        }
        match m - row {
            0 => {}
            1 => block::<S, 1, C, MASKED>(p, row, col, lanes),
            2 => block::<S, 2, C, MASKED>(p, row, col, lanes),
            rest => {
                debug_assert_eq!(rest, 3);
                block::<S, 3, C, MASKED>(p, row, col, lanes)
            }
        }
    }
}

/// Rows `row..row + R`, columns `col..col + C * WIDTH` (the last vector's first `lanes` columns if `MASKED`):
/// `R x C` accumulators over the whole `k` loop.
#[inline(always)]
unsafe fn block<S: Lanes, const R: usize, const C: usize, const MASKED: bool>(
    p: &Operands,
    row: usize,
    col: usize,
    lanes: usize,
) {
    let load = |ptr: *const f32, c: usize| {
        // SAFETY: forwarded from `product` (the caller's pointer is inside the checked shapes).
        unsafe {
            if MASKED && c == C - 1 {
                S::load_first(ptr, lanes)
            } else {
                S::load(ptr)
            }
        }
    };
    // SAFETY: forwarded from `product` (every pointer offset is inside the checked shapes).
    unsafe {
        let start = match p.init {
            Some(bias) => {
                let mut v = [S::splat(0.0); C];
                for (c, v) in v.iter_mut().enumerate() {
                    *v = load(bias.add(col + c * S::WIDTH), c);
                }
                v
            }
            None => [S::splat(0.0); C],
        };
        let mut acc = [start; R];
        let mut a_ptr = p.a.add(row * p.a_rs);
        let mut b_ptr = p.b.add(col);
        for _ in 0..p.k {
            let mut bv = [S::splat(0.0); C];
            for (c, v) in bv.iter_mut().enumerate() {
                *v = load(b_ptr.add(c * S::WIDTH), c);
            }
            for (r, acc_row) in acc.iter_mut().enumerate() {
                let av = S::splat(*a_ptr.add(r * p.a_rs));
                for (acc, &bv) in acc_row.iter_mut().zip(&bv) {
                    *acc = S::fma(av, bv, *acc);
                }
            }
            a_ptr = a_ptr.add(p.a_cs);
            b_ptr = b_ptr.add(p.n);
        }
        for (r, acc_row) in acc.iter().enumerate() {
            let out = p.dst.add((row + r) * p.n + col);
            for (c, &v) in acc_row.iter().enumerate() {
                if MASKED && c == C - 1 {
                    S::store_first(out.add(c * S::WIDTH), v, lanes);
                } else {
                    S::store(out.add(c * S::WIDTH), v);
                }
            }
        }
    }
}

/// ReLU backward in place: `grad` zeroed (+0) wherever the layer's post-ReLU output `activations` is not
/// positive, `WIDTH` lanes at a time. Written with the level's vectors because LLVM vectorises the plain loop
/// into masked stores (`vmaskmovps`), which AMD CPUs run in microcode: 15% of the backward pass on an EPYC.
#[inline(always)]
pub(crate) fn relu_backward<S: Lanes>(grad: &mut [f32], activations: &[f32]) {
    assert_eq!(
        grad.len(),
        activations.len(),
        "relu_backward: lengths differ"
    );
    let vectors = grad.len() / S::WIDTH * S::WIDTH;
    let (body, tail) = grad.split_at_mut(vectors);
    for (i, g) in body.chunks_exact_mut(S::WIDTH).enumerate() {
        // SAFETY: `g` and the activations at the same offset hold WIDTH floats each.
        unsafe {
            let a = S::load(activations.as_ptr().add(i * S::WIDTH));
            S::store(
                g.as_mut_ptr(),
                S::keep_where_positive(S::load(g.as_ptr()), a),
            );
        }
    }
    for (g, &a) in tail.iter_mut().zip(&activations[vectors..]) {
        // SAFETY: the scalar level has no target feature.
        *g = unsafe { Scalar::keep_where_positive(*g, a) };
    }
}

/// Writes the transpose of the row-major `rows x cols` matrix `src` into `dst` (`cols x rows`): in 8 x 8
/// blocks in vector registers on the vector levels, the edges (and the scalar level) element by element.
/// Moves only, no arithmetic: every level writes the same bytes.
#[inline(always)]
pub(crate) fn transpose<S: Lanes>(src: &[f32], rows: usize, cols: usize, dst: &mut [f32]) {
    assert!(src.len() >= rows * cols && dst.len() >= rows * cols);
    let (block_rows, block_cols) = if S::TRANSPOSES_BLOCKS {
        (rows / 8 * 8, cols / 8 * 8)
    } else {
        (0, 0)
    };
    for r in (0..block_rows).step_by(8) {
        for c in (0..block_cols).step_by(8) {
            // SAFETY: rows r..r+8 and columns c..c+8 lie inside `src` (rows x cols), and rows c..c+8, columns
            // r..r+8 inside `dst` (cols x rows), by the assert above.
            unsafe {
                S::transpose8(
                    src.as_ptr().add(r * cols + c),
                    cols,
                    dst.as_mut_ptr().add(c * rows + r),
                    rows,
                )
            };
        }
    }
    // The right edge of the blocked rows, then every column of the rows below them.
    for r in 0..rows {
        let first = if r < block_rows { block_cols } else { 0 };
        for c in first..cols {
            dst[c * rows + r] = src[r * cols + c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::SimdLevel;

    fn reference(a: Strided, b: &[f32], n: usize, init: Option<&[f32]>) -> Vec<f32> {
        let mut out = vec![0.0f32; a.rows * n];
        for r in 0..a.rows {
            for c in 0..n {
                let mut acc = init.map_or(0.0, |bias| bias[c]);
                for k in 0..a.cols {
                    acc = a.data[r * a.row_stride + k * a.col_stride].mul_add(b[k * n + c], acc);
                }
                out[r * n + c] = acc;
            }
        }
        out
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn product_avx2(dst: &mut [f32], a: Strided, b: &[f32], init: Option<&[f32]>) {
        product::<Avx2>(dst, a, b, init)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    fn product_avx512(dst: &mut [f32], a: Strided, b: &[f32], init: Option<&[f32]>) {
        product::<Avx512>(dst, a, b, init)
    }

    /// Every available path equals the one-element-at-a-time FMA chain bit for bit, for shapes with
    /// leftover rows and columns, strided (transposed) left operands, with and without a bias; and the
    /// result agrees with an f64 product to rounding.
    #[test]
    fn every_level_computes_the_same_fma_chain_bit_for_bit() {
        let detected = SimdLevel::detected();
        // Every column rest of every level (1-40 columns), for row counts with and without leftover blocks.
        let rests = [1, 3, 9, 20, 32]
            .into_iter()
            .flat_map(|m| (1..=40).map(move |n| (m, 7, n)));
        for (m, k, n) in rests.chain([
            (1, 3, 64),
            (5, 64, 64),
            (7, 13, 40),
            (32, 64, 4),
            (3, 5, 17),
            (9, 2, 1),
            (6, 64, 2),
            (5, 64, 3),
            (32, 64, 20),
            (7, 9, 22),
            (5, 64, 30),
            (3, 4, 15),
            (64, 32, 2),
            (64, 32, 4),
            (80, 5, 3),
            (100, 9, 7),
            (256, 3, 1),
            (71, 4, 15),
            (48, 6, 5),
        ]) {
            let a_data: Vec<f32> = (0..m * k)
                .map(|i| ((i * 37 % 101) as f32 - 50.0) * 0.013)
                .collect();
            let b: Vec<f32> = (0..k * n)
                .map(|i| ((i * 53 % 97) as f32 - 48.0) * 0.021)
                .collect();
            let bias: Vec<f32> = (0..n).map(|i| i as f32 * 0.1 - 1.0).collect();
            for transposed in [false, true] {
                let a = if transposed {
                    Strided::transposed(&a_data, k, m)
                } else {
                    Strided::row_major(&a_data, m, k)
                };
                for init in [None, Some(&bias[..])] {
                    let expected = reference(a, &b, n, init);
                    let mut out = vec![f32::NAN; m * n];
                    product::<Scalar>(&mut out, a, &b, init);
                    assert_eq!(out, expected, "scalar {m}x{k}x{n}");
                    #[cfg(target_arch = "x86_64")]
                    {
                        // Written into the front of a longer buffer: nothing may land past `m * n`.
                        let mut buf = vec![f32::NAN; m * n + 8];
                        if detected >= SimdLevel::Avx2 {
                            buf.fill(f32::NAN);
                            // SAFETY: the CPU has AVX2 and FMA.
                            unsafe { product_avx2(&mut buf[..m * n], a, &b, init) };
                            assert_eq!(buf[..m * n], expected, "avx2 {m}x{k}x{n}");
                            assert!(buf[m * n..].iter().all(|v| v.is_nan()), "avx2 wrote past");
                        }
                        if detected >= SimdLevel::Avx512 {
                            buf.fill(f32::NAN);
                            // SAFETY: the CPU has AVX-512F.
                            unsafe { product_avx512(&mut buf[..m * n], a, &b, init) };
                            assert_eq!(buf[..m * n], expected, "avx512 {m}x{k}x{n}");
                            assert!(buf[m * n..].iter().all(|v| v.is_nan()), "avx512 wrote past");
                        }
                    }
                    for r in 0..m {
                        for c in 0..n {
                            let mut exact = init.map_or(0.0, |bias| bias[c] as f64);
                            for kk in 0..k {
                                exact += a.data[r * a.row_stride + kk * a.col_stride] as f64
                                    * b[kk * n + c] as f64;
                            }
                            assert!((expected[r * n + c] as f64 - exact).abs() < 1e-4);
                        }
                    }
                }
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn transpose_avx2(src: &[f32], rows: usize, cols: usize, dst: &mut [f32]) {
        transpose::<Avx2>(src, rows, cols, dst)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    fn transpose_avx512(src: &[f32], rows: usize, cols: usize, dst: &mut [f32]) {
        transpose::<Avx512>(src, rows, cols, dst)
    }

    /// Every level puts element `(r, c)` at `(c, r)`, for shapes with and without whole 8 x 8 blocks and with
    /// edges on either side, and writes nothing past the transpose.
    #[test]
    fn transpose_moves_every_element() {
        let src: Vec<f32> = (0..6).map(|i| i as f32).collect();
        let mut dst = vec![0.0; 6];
        transpose::<Scalar>(&src, 2, 3, &mut dst);
        assert_eq!(dst, [0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
        let detected = SimdLevel::detected();
        for (rows, cols) in [
            (2, 3),
            (8, 8),
            (64, 64),
            (64, 2),
            (2, 64),
            (17, 9),
            (9, 24),
            (16, 40),
            (7, 7),
        ] {
            let src: Vec<f32> = (0..rows * cols).map(|i| i as f32 + 0.5).collect();
            let expected: Vec<f32> = (0..cols * rows)
                .map(|i| src[(i % rows) * cols + i / rows])
                .collect();
            let mut dst = vec![f32::NAN; rows * cols + 8];
            transpose::<Scalar>(&src, rows, cols, &mut dst);
            assert_eq!(dst[..rows * cols], expected, "scalar {rows}x{cols}");
            #[cfg(target_arch = "x86_64")]
            {
                if detected >= SimdLevel::Avx2 {
                    dst.fill(f32::NAN);
                    // SAFETY: the CPU has AVX2 and FMA.
                    unsafe { transpose_avx2(&src, rows, cols, &mut dst) };
                    assert_eq!(dst[..rows * cols], expected, "avx2 {rows}x{cols}");
                    assert!(
                        dst[rows * cols..].iter().all(|v| v.is_nan()),
                        "avx2 wrote past"
                    );
                }
                if detected >= SimdLevel::Avx512 {
                    dst.fill(f32::NAN);
                    // SAFETY: the CPU has AVX-512F.
                    unsafe { transpose_avx512(&src, rows, cols, &mut dst) };
                    assert_eq!(dst[..rows * cols], expected, "avx512 {rows}x{cols}");
                    assert!(
                        dst[rows * cols..].iter().all(|v| v.is_nan()),
                        "avx512 wrote past"
                    );
                }
            }
        }
    }
}
