// conv2d.cu - 2-D convolution, stride 1, "same" output size (padding KH/2, KW/2), odd kernels,
// zero (pad_mode 0) or replicate (pad_mode 1) padding; forward, input gradient, weight gradient,
// bias gradient. Contract: anisocb::ops::conv2d::{conv2d_ref, conv2d_backward_ref}.
//
// Layouts (row-major): x (N, C, H, W), w (O, C, KH, KW) (OIHW), b (O), y / dy (N, O, H, W).
//
// All three products are implicit GEMMs on (16*MI) x 64 output tiles: 256 threads, each owning
// an MI x 4 micro-tile (rows ty + 16*i, columns tx + 16*j), reduction slices of BK = 16 staged in
// shared memory. Each kernel comes in two tile heights: MI = 4 (64 rows; `conv2d_fwd`, ...) and
// MI = 2 (32 rows; `..._m32`, for GEMMs of at most 32 rows, where half a 64-row tile would be
// zeros); both give the same bits (every output is summed in the same order). Every kernel
// writes each output once and reduces in a fixed order: results are bit-for-bit reproducible
// run to run (no atomics).
//
// Fused epilogues (device-resident training, src/cuda/train.rs): the forward's store can apply
// the ReLU or the residual skip that follows the conv, and the input gradient's store the ReLU's
// backward, each with the element-wise kernel's own expression (elementwise.cu), so the fused
// result has the bits of the conv followed by that kernel.

#define BN 64
#define BK 16
#define NT 256

// conv2d_fwd's `epi`: what its store does with v = acc + bias (acc alone with dgrad = 1).
#define EPI_NONE 0  // y = v; with dgrad, y += acc
#define EPI_RELU 1  // y = v < 0 ? 0 : v                      (relu_fwd)
#define EPI_ADD 2   // y = v + aux[the same index]             (add_assign: the residual skip)
#define EPI_MASK 3  // dgrad only: y += aux[same] > 0 ? acc : 0 (relu_bwd, aux the ReLU's output)

// Source index of padded coordinate p in [0, n), or -1 where zero padding reads a 0.
__device__ __forceinline__ int pad_idx(int p, int n, int mode) {
    if (p >= 0 && p < n) return p;
    if (mode == 0) return -1;
    return p < 0 ? 0 : n - 1;
}

// acc[i][j] += sum_kk As[kk][ty + 16 i] * Bs[kk][tx + 16 j]
template <int MI>
__device__ __forceinline__ void mma_tile(float (*As)[16 * MI + 1], float (*Bs)[BN],
                                         float acc[MI][4], int tx, int ty) {
#pragma unroll
    for (int kk = 0; kk < BK; ++kk) {
        float a[MI], b[4];
#pragma unroll
        for (int i = 0; i < MI; ++i) a[i] = As[kk][ty + 16 * i];
#pragma unroll
        for (int j = 0; j < 4; ++j) b[j] = Bs[kk][tx + 16 * j];
#pragma unroll
        for (int i = 0; i < MI; ++i)
#pragma unroll
            for (int j = 0; j < 4; ++j) acc[i][j] = fmaf(a[i], b[j], acc[i][j]);
    }
}

// Zeroed accumulators of an MI x 4 micro-tile.
#define ACC_ZERO(acc) float acc[MI][4] = {};

// Forward. GEMM y[o, p] = b[o] + sum_k w[o, k] * im2col[k, p], with
//   o < O (tile rows, blockIdx.y), p = (n, yy, xx) < N*H*W (tile columns, blockIdx.x),
//   k = (c*KH + ky)*KW + kx < C*KH*KW, im2col[k, p] = x[n, c, pad(yy + ky - KH/2), pad(xx + kx - KW/2)].
// grid (ceil(N*H*W / 64), ceil(O / (16*MI))), block 256.
// dgrad = 1: the input gradient of a zero-padded conv as this forward, y += conv(dy, w'): x is
// that conv's dy (C here = its O), w its own weight (C x O x KH x KW, here O = its C) read as
// w'[o, c, ky, kx] = w[c, o, KH-1-ky, KW-1-kx], no bias, and y (its dx) accumulated.
// epi: EPI_* above; aux (N, O, H, W) is read by EPI_ADD and EPI_MASK only.
template <int MI>
__device__ __forceinline__ void conv2d_fwd_t(const float* __restrict__ x, const float* __restrict__ w,
                                             const float* __restrict__ bias, float* __restrict__ y,
                                             int N, int C, int H, int W, int O, int KH, int KW,
                                             int pad_mode, int has_bias, int dgrad,
                                             const float* __restrict__ aux, int epi) {
    constexpr int BMv = 16 * MI;
    __shared__ float As[BK][BMv + 1];
    __shared__ float Bs[BK][BN];
    const int tid = threadIdx.x, tx = tid & 15, ty = tid >> 4;
    const int HW = H * W, P = N * HW, KK = KH * KW, K = C * KK;
    const int ph = KH / 2, pw = KW / 2;
    const int m0 = blockIdx.y * BMv, n0 = blockIdx.x * BN;

    // B loader: this thread always fills column bn (one pixel) of the tile.
    const int bn = tid & (BN - 1);
    const int p = n0 + bn;
    const bool p_ok = p < P;
    int pn = 0, py = 0, px = 0;
    if (p_ok) {
        pn = p / HW;
        const int r = p - pn * HW;
        py = r / W;
        px = r - py * W;
    }
    const float* xn = x + (long long)pn * C * HW;

    ACC_ZERO(acc)

    for (int k0 = 0; k0 < K; k0 += BK) {
        // A tile (16*MI x 16): As[kk][mm] = w[m0 + mm, k0 + kk] (w' with dgrad)
#pragma unroll
        for (int i = 0; i < MI; ++i) {
            const int e = tid + NT * i;
            const int mm = e / BK, kk = e % BK;
            const int m = m0 + mm, k = k0 + kk;
            float v = 0.f;
            if (m < O && k < K) {
                if (dgrad) {
                    const int c = k / KK;
                    v = w[((long long)c * O + m) * KK + (KK - 1 - (k - c * KK))];
                } else {
                    v = w[(long long)m * K + k];
                }
            }
            As[kk][mm] = v;
        }
        // B tile (16 x 64): Bs[kk][bn] = im2col[k0 + kk, p]
#pragma unroll
        for (int i = 0; i < 4; ++i) {
            const int kk = tid / BN + (NT / BN) * i;
            const int k = k0 + kk;
            float v = 0.f;
            if (p_ok && k < K) {
                const int c = k / KK;
                const int t = k - c * KK;
                const int ky = t / KW, kx = t - (t / KW) * KW;
                const int sy = pad_idx(py + ky - ph, H, pad_mode);
                const int sx = pad_idx(px + kx - pw, W, pad_mode);
                if (sy >= 0 && sx >= 0) v = xn[(long long)c * HW + sy * W + sx];
            }
            Bs[kk][bn] = v;
        }
        __syncthreads();
        mma_tile<MI>(As, Bs, acc, tx, ty);
        __syncthreads();
    }

#pragma unroll
    for (int i = 0; i < MI; ++i) {
        const int m = m0 + ty + 16 * i;
        if (m >= O) continue;
        const float b = has_bias ? bias[m] : 0.f;
#pragma unroll
        for (int j = 0; j < 4; ++j) {
            const int q = n0 + tx + 16 * j;
            if (q >= P) continue;
            const int qn = q / HW;
            const int r = q - qn * HW;
            const long long at = ((long long)qn * O + m) * HW + r;
            const float a = acc[i][j];
            if (dgrad) {
                y[at] += epi == EPI_MASK ? (aux[at] > 0.f ? a : 0.f) : a;
            } else {
                const float v = a + b;
                y[at] = epi == EPI_RELU ? (v < 0.f ? 0.f : v) : epi == EPI_ADD ? v + aux[at] : v;
            }
        }
    }
}

#define CONV2D_FWD_ARGS                                                                             \
    const float *__restrict__ x, const float *__restrict__ w, const float *__restrict__ bias,       \
        float *__restrict__ y, int N, int C, int H, int W, int O, int KH, int KW, int pad_mode, \
        int has_bias, int dgrad, const float *__restrict__ aux, int epi
extern "C" __global__ void conv2d_fwd(CONV2D_FWD_ARGS) {
    conv2d_fwd_t<4>(x, w, bias, y, N, C, H, W, O, KH, KW, pad_mode, has_bias, dgrad, aux, epi);
}
extern "C" __global__ void conv2d_fwd_m32(CONV2D_FWD_ARGS) {
    conv2d_fwd_t<2>(x, w, bias, y, N, C, H, W, O, KH, KW, pad_mode, has_bias, dgrad, aux, epi);
}

// Weight gradient, split over the reduction: for reduction chunk z (pixels [z*chunk, (z+1)*chunk)),
//   part[z, o, k] = sum_p dy[n, o, yy, xx] * im2col[k, p]        (p = (n, yy, xx), k as in conv2d_fwd)
// Tile rows o < O (blockIdx.y), columns k < C*KH*KW (blockIdx.x), chunk index blockIdx.z.
// `chunk` is a multiple of BK. part: (Z, O, C*KH*KW). Summed by conv2d_wgrad_reduce.
template <int MI>
__device__ __forceinline__ void conv2d_wgrad_t(const float* __restrict__ x, const float* __restrict__ dy,
                                               float* __restrict__ part, int N, int C, int H, int W,
                                               int O, int KH, int KW, int pad_mode, int chunk) {
    constexpr int BMv = 16 * MI;
    __shared__ float As[BK][BMv + 1];
    __shared__ float Bs[BK][BN];
    const int tid = threadIdx.x, tx = tid & 15, ty = tid >> 4;
    const int HW = H * W, P = N * HW, KK = KH * KW, K = C * KK;
    const int ph = KH / 2, pw = KW / 2;
    const int m0 = blockIdx.y * BMv, n0 = blockIdx.x * BN;
    const int pbeg = blockIdx.z * chunk;
    const int pend = pbeg + chunk < P ? pbeg + chunk : P;

    // B loader: this thread always fills column bn (one weight index k) of the tile.
    const int bn = tid & (BN - 1);
    const int kcol = n0 + bn;
    const bool k_ok = kcol < K;
    int bc = 0, bky = 0, bkx = 0;
    if (k_ok) {
        bc = kcol / KK;
        const int t = kcol - bc * KK;
        bky = t / KW;
        bkx = t - bky * KW;
    }

    ACC_ZERO(acc)

    for (int p0 = pbeg; p0 < pend; p0 += BK) {
        // A tile: As[kk][mm] = dy[o = m0 + mm, p = p0 + kk]
#pragma unroll
        for (int i = 0; i < MI; ++i) {
            const int e = tid + NT * i;
            const int mm = e / BK, kk = e % BK;
            const int m = m0 + mm, pp = p0 + kk;
            float v = 0.f;
            if (m < O && pp < pend) {
                const int nn = pp / HW;
                const int r = pp - nn * HW;
                v = dy[((long long)nn * O + m) * HW + r];
            }
            As[kk][mm] = v;
        }
        // B tile: Bs[kk][bn] = im2col[kcol, p0 + kk]
#pragma unroll
        for (int i = 0; i < 4; ++i) {
            const int kk = tid / BN + (NT / BN) * i;
            const int pp = p0 + kk;
            float v = 0.f;
            if (k_ok && pp < pend) {
                const int nn = pp / HW;
                const int r = pp - nn * HW;
                const int yy = r / W, xx = r - (r / W) * W;
                const int sy = pad_idx(yy + bky - ph, H, pad_mode);
                const int sx = pad_idx(xx + bkx - pw, W, pad_mode);
                if (sy >= 0 && sx >= 0) v = x[((long long)nn * C + bc) * HW + sy * W + sx];
            }
            Bs[kk][bn] = v;
        }
        __syncthreads();
        mma_tile<MI>(As, Bs, acc, tx, ty);
        __syncthreads();
    }

    float* pz = part + (long long)blockIdx.z * O * K;
#pragma unroll
    for (int i = 0; i < MI; ++i) {
        const int m = m0 + ty + 16 * i;
        if (m >= O) continue;
#pragma unroll
        for (int j = 0; j < 4; ++j) {
            const int k = n0 + tx + 16 * j;
            if (k < K) pz[(long long)m * K + k] = acc[i][j];
        }
    }
}

#define CONV2D_WGRAD_ARGS                                                                        \
    const float *__restrict__ x, const float *__restrict__ dy, float *__restrict__ part, int N, \
        int C, int H, int W, int O, int KH, int KW, int pad_mode, int chunk
extern "C" __global__ void conv2d_wgrad(CONV2D_WGRAD_ARGS) {
    conv2d_wgrad_t<4>(x, dy, part, N, C, H, W, O, KH, KW, pad_mode, chunk);
}
extern "C" __global__ void conv2d_wgrad_m32(CONV2D_WGRAD_ARGS) {
    conv2d_wgrad_t<2>(x, dy, part, N, C, H, W, O, KH, KW, pad_mode, chunk);
}

// dw[i] += sum_{z < Z} part[z, i], i < len (= O*C*KH*KW), summed in z order. 1-D grid-stride.
extern "C" __global__ void conv2d_wgrad_reduce(const float* __restrict__ part, float* __restrict__ dw,
                                               int Z, long long len) {
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < len;
         i += (long long)gridDim.x * blockDim.x) {
        float s = 0.f;
        for (int z = 0; z < Z; ++z) s += part[(long long)z * len + i];
        dw[i] += s;
    }
}

// Input gradient on the padded grid (Hp = H + KH - 1, Wp = W + KW - 1):
//   dxp[n, c, py, px] = sum_{o, ky, kx} w[o, c, ky, kx] * dy[n, o, py - ky, px - kx]   (dy is 0 outside)
// GEMM rows c < C (blockIdx.y), columns q = (n, py, px) < N*Hp*Wp (blockIdx.x),
// reduction k = (o*KH + ky)*KW + kx < O*KH*KW. conv2d_dgrad_fold folds dxp onto dx. (Replicate
// padding; a zero-padded conv's input gradient is conv2d_fwd with dgrad = 1.)
template <int MI>
__device__ __forceinline__ void conv2d_dgrad_padded_t(const float* __restrict__ w,
                                                      const float* __restrict__ dy,
                                                      float* __restrict__ dxp, int N, int C, int H,
                                                      int W, int O, int KH, int KW) {
    constexpr int BMv = 16 * MI;
    __shared__ float As[BK][BMv + 1];
    __shared__ float Bs[BK][BN];
    const int tid = threadIdx.x, tx = tid & 15, ty = tid >> 4;
    const int HW = H * W, KK = KH * KW, K = O * KK;
    const int Hp = H + KH - 1, Wp = W + KW - 1, HWp = Hp * Wp, P = N * HWp;
    const int m0 = blockIdx.y * BMv, n0 = blockIdx.x * BN;

    // B loader: this thread always fills column bn (one padded pixel) of the tile.
    const int bn = tid & (BN - 1);
    const int q = n0 + bn;
    const bool q_ok = q < P;
    int qn = 0, py = 0, px = 0;
    if (q_ok) {
        qn = q / HWp;
        const int r = q - qn * HWp;
        py = r / Wp;
        px = r - py * Wp;
    }
    const float* dyn = dy + (long long)qn * O * HW;

    ACC_ZERO(acc)

    for (int k0 = 0; k0 < K; k0 += BK) {
        // A tile: As[kk][mm] = w[o, c = m0 + mm, t] with k0 + kk = o*KK + t
#pragma unroll
        for (int i = 0; i < MI; ++i) {
            const int e = tid + NT * i;
            const int mm = e / BK, kk = e % BK;
            const int c = m0 + mm, k = k0 + kk;
            float v = 0.f;
            if (c < C && k < K) {
                const int o = k / KK;
                const int t = k - o * KK;
                v = w[((long long)o * C + c) * KK + t];
            }
            As[kk][mm] = v;
        }
        // B tile: Bs[kk][bn] = dy[qn, o, py - ky, px - kx]
#pragma unroll
        for (int i = 0; i < 4; ++i) {
            const int kk = tid / BN + (NT / BN) * i;
            const int k = k0 + kk;
            float v = 0.f;
            if (q_ok && k < K) {
                const int o = k / KK;
                const int t = k - o * KK;
                const int ky = t / KW, kx = t - (t / KW) * KW;
                const int yy = py - ky, xx = px - kx;
                if (yy >= 0 && yy < H && xx >= 0 && xx < W) v = dyn[(long long)o * HW + yy * W + xx];
            }
            Bs[kk][bn] = v;
        }
        __syncthreads();
        mma_tile<MI>(As, Bs, acc, tx, ty);
        __syncthreads();
    }

#pragma unroll
    for (int i = 0; i < MI; ++i) {
        const int c = m0 + ty + 16 * i;
        if (c >= C) continue;
#pragma unroll
        for (int j = 0; j < 4; ++j) {
            const int qq = n0 + tx + 16 * j;
            if (qq >= P) continue;
            const int nn = qq / HWp;
            const int r = qq - nn * HWp;
            dxp[((long long)nn * C + c) * HWp + r] = acc[i][j];
        }
    }
}

#define CONV2D_DGRAD_ARGS                                                                          \
    const float *__restrict__ w, const float *__restrict__ dy, float *__restrict__ dxp, int N, int C, \
        int H, int W, int O, int KH, int KW
extern "C" __global__ void conv2d_dgrad_padded(CONV2D_DGRAD_ARGS) {
    conv2d_dgrad_padded_t<4>(w, dy, dxp, N, C, H, W, O, KH, KW);
}
extern "C" __global__ void conv2d_dgrad_padded_m32(CONV2D_DGRAD_ARGS) {
    conv2d_dgrad_padded_t<2>(w, dy, dxp, N, C, H, W, O, KH, KW);
}

// dx[nc, sy, sx] += sum dxp[nc, py, px] over the padded pixels that read (sy, sx):
// zero padding: only (sy + KH/2, sx + KW/2); replicate: border pixels also collect the halo.
// dxp: (NC, H + KH - 1, W + KW - 1), dx: (NC, H, W). 1-D grid-stride over NC*H*W.
// masked = 1: dx += mask > 0 ? sum : 0, mask (NC, H, W) the ReLU output x is (relu_bwd fused).
extern "C" __global__ void conv2d_dgrad_fold(const float* __restrict__ dxp, float* __restrict__ dx,
                                             int NC, int H, int W, int KH, int KW, int pad_mode,
                                             const float* __restrict__ mask, int masked) {
    const int ph = KH / 2, pw = KW / 2;
    const int Hp = H + KH - 1, Wp = W + KW - 1;
    const long long HW = (long long)H * W, total = (long long)NC * HW;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < total;
         i += (long long)gridDim.x * blockDim.x) {
        const long long nc = i / HW;
        const int r = (int)(i - nc * HW);
        const int sy = r / W, sx = r - (r / W) * W;
        int ylo = sy + ph, yhi = sy + ph, xlo = sx + pw, xhi = sx + pw;
        if (pad_mode == 1) {
            if (sy == 0) ylo = 0;
            if (sy == H - 1) yhi = Hp - 1;
            if (sx == 0) xlo = 0;
            if (sx == W - 1) xhi = Wp - 1;
        }
        const float* src = dxp + (long long)nc * Hp * Wp;
        float s = 0.f;
        for (int py = ylo; py <= yhi; ++py)
            for (int px = xlo; px <= xhi; ++px) s += src[py * Wp + px];
        dx[i] += masked ? (mask[i] > 0.f ? s : 0.f) : s;
    }
}

// db[o] += sum_{n, yy, xx} dy[n, o, yy, xx]. grid (O), block 256 (a power of two).
extern "C" __global__ void conv2d_bias_grad(const float* __restrict__ dy, float* __restrict__ db,
                                            int N, int O, int HW) {
    __shared__ float red[NT];
    const int o = blockIdx.x;
    float s = 0.f;
    for (int n = 0; n < N; ++n) {
        const float* src = dy + ((long long)n * O + o) * HW;
        for (int i = threadIdx.x; i < HW; i += blockDim.x) s += src[i];
    }
    red[threadIdx.x] = s;
    __syncthreads();
    for (int h = blockDim.x / 2; h > 0; h >>= 1) {
        if ((int)threadIdx.x < h) red[threadIdx.x] += red[threadIdx.x + h];
        __syncthreads();
    }
    if (threadIdx.x == 0) db[o] += red[0];
}
