// infer.cu - the device-resident inference of a whole bundle (anisocb::cuda::infer): every net of
// the bundle and every mirror view of a chunk of frames in one batch, activations kept on the
// device in fp16 NHWC, 3x3 convolutions on the tensor cores (mma.sync m16n8k16, fp16 operands,
// fp32 accumulation) with the epilogue (bias, residual skip, ReLU, pixel shuffle) fused into the
// store. Contract: anisocb::nn::AnisoCb::forward_with on each view, un-mirrored and averaged, as
// sr::upscale::run_nets_into does op by op; fp16 rounding is the difference (tests/cuda_parity.rs).
//
// Layouts. "Z" indexes the nets of the bundle (the GeometryNets first, then BoundaryNet, then
// EnhanceNet), "NB" the images of the batch (view v of frame n at v*N + n). Activations:
// (Z, NB, H, W, CP) fp16, CP a multiple of 16 (padded channels hold 0). Weights of one layer:
// (Z, COP, 9*CI) fp16, k = (ky*3 + kx)*CI + c, zero for padded rows and columns; bias (Z, COP).
// Needs sm_80 or newer (mma.sync with f16 operands); compiled for compute_80.

#define TC_COUT 32  // output channels of a block: four n8 tiles

#ifndef ANISOCB_EMU
__device__ __forceinline__ unsigned short f2h(float x) {
    unsigned short h;
    asm("cvt.rn.f16.f32 %0, %1;" : "=h"(h) : "f"(x));
    return h;
}
__device__ __forceinline__ float h2f(unsigned short h) {
    float x;
    asm("cvt.f32.f16 %0, %1;" : "=f"(x) : "h"(h));
    return x;
}
// d += a * b for one warp: a the 16x16 A fragment (four .f16x2 registers), b the 16x8 B fragment
// (two), d the 16x8 fp32 accumulator (four), in the PTX ISA's m16n8k16 fragment layouts.
__device__ __forceinline__ void mma16816(float* d, const unsigned* a, const unsigned* b) {
    asm volatile(
        "mma.sync.aligned.m16n8k16.row.col.f32.f16.f16.f32 {%0,%1,%2,%3}, {%4,%5,%6,%7}, {%8,%9}, "
        "{%0,%1,%2,%3};\n"
        : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3])
        : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b[0]), "r"(b[1]));
}
#endif

__device__ __forceinline__ int tc_pad(int p, int n, int mode) {  // mode 0 zero (-1), 1 replicate
    if (p >= 0 && p < n) return p;
    if (mode == 0) return -1;
    return p < 0 ? 0 : n - 1;
}

// fp32 -> fp16 (round to nearest even), 1-D grid-stride over n.
extern "C" __global__ void f32_to_f16(const float* __restrict__ x, unsigned short* __restrict__ y, long long n) {
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n;
         i += (long long)gridDim.x * blockDim.x)
        y[i] = f2h(x[i]);
}

// The views of a chunk, fp16 NHWC. x: (N, 3, H, W) fp32 -> y: (V*N, H, W, CP) fp16; view v of frame
// n is image v*N + n: rows flipped if bit 0 of its flags, columns if bit 1, and channel ch (< 3)
// replaced by 1 - value if bit 2 + ch (a mirrored axis of the cloth frame). flags: 8 bits a view,
// view v at bits 8v. Channels 3..CP-1 are 0. 1-D grid-stride over V*N*H*W pixels.
extern "C" __global__ void views_to_nhwc(const float* __restrict__ x, unsigned short* __restrict__ y,
                                         int V, int N, int H, int W, int CP, int flags) {
    const long long HW = (long long)H * W, total = (long long)V * N * HW;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < total;
         i += (long long)gridDim.x * blockDim.x) {
        const long long img = i / HW;
        const int r = (int)(i - img * HW);
        const int v = (int)(img / N), n = (int)(img - (long long)v * N);
        const int f = (flags >> (8 * v)) & 255;
        int yy = r / W, xx = r - (r / W) * W;
        if (f & 1) yy = H - 1 - yy;
        if (f & 2) xx = W - 1 - xx;
        unsigned short* out = y + i * CP;
        for (int ch = 0; ch < CP; ++ch) {
            float val = 0.f;
            if (ch < 3) {
                val = x[((long long)n * 3 + ch) * HW + yy * W + xx];
                if ((f >> (2 + ch)) & 1) val = 1.f - val;
            }
            out[ch] = f2h(val);
        }
    }
}

// One 3x3 convolution ("same" size, stride 1) of every net on the tensor cores.
//   x: (Z, NB, H, W, CI) fp16 (xz: elements between nets, 0 = one input shared by all nets)
//   w: (Z, COP, 9*CI) fp16, b: (Z, COP) fp32; CI a multiple of 16, COP of 8
//   acc[q, o] = b[o] + sum_{ky, kx, c} w[o, (ky*3 + kx)*CI + c] * x[pad(q + (ky-1, kx-1)), c]
// then by mode:
//   0: + skip[q, o] (fp16, like y, nets z < nskip only), ReLU if relu, y (Z, NB, H, W, COP) fp16
//   1: pixel shuffle x2: o = c*4 + i*2 + j -> y (Z, NB, 2H, 2W, COP/4) at (2y + i, 2x + j, c) fp16
//   2: y (Z, NB, CO, H, W) fp32, channels o < (z < ng ? co_geo : co_map) only (the nets' outputs)
// pad_mode 0 zero, 1 replicate.
// A block computes an 8 x 16 pixel tile of one image and 32 output channels: per slab of 32
// input channels it stages the tile with its one-pixel halo (padding applied as it loads) and
// the slab of the 32 channels' weights in shared memory, then each of its 4 warps runs the 9 taps
// on two tile rows (two m16 tiles) x four n8 tiles from there. Row strides are padded by 8 halves
// so that a warp's fragment loads hit 32 different banks.
// Grid (ceil(W/16) * ceil(H/8), ceil(COP/32), Z*NB), block 128.
#define TC_MT 2  // m16 tiles (tile rows) of a warp; infer.rs's TC_TILE rows = 4 * TC_MT
#define TC_TH (4 * TC_MT)
#define TC_TW 16
#define TC_HALO_H (TC_TH + 2)
#define TC_HALO_W (TC_TW + 2)
#define TC_SLAB 32
#define TC_A_STRIDE (TC_SLAB + 8)
#define TC_W_STRIDE (9 * TC_SLAB + 8)
extern "C" __global__ void conv3x3_tc(const unsigned short* __restrict__ x, long long xz,
                                      const unsigned short* __restrict__ w, const float* __restrict__ b,
                                      const unsigned short* __restrict__ skip, void* __restrict__ y,
                                      int NB, int H, int W, int CI, int COP, int pad_mode, int mode,
                                      int relu, int nskip, int ng, int CO, int co_geo, int co_map) {
    __shared__ __align__(16) unsigned short As[TC_HALO_H * TC_HALO_W * TC_A_STRIDE];
    __shared__ __align__(16) unsigned short Ws[TC_COUT * TC_W_STRIDE];
    const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
    const int g = lane >> 2, t = lane & 3;
    const int HW = H * W, K9 = 9 * CI;
    const int tiles_x = (W + TC_TW - 1) / TC_TW;
    const int ty0 = (blockIdx.x / tiles_x) * TC_TH, tx0 = (blockIdx.x % tiles_x) * TC_TW;
    const int z = blockIdx.z / NB, img = blockIdx.z - (blockIdx.z / NB) * NB;
    const int n0 = blockIdx.y * TC_COUT;
    const unsigned short* xi = x + (long long)z * xz + (long long)img * HW * CI;
    w += (long long)z * COP * K9;
    b += (long long)z * COP;
    int nt = (COP - n0) / 8;  // n8 tiles of this block (COP is a multiple of 8)
    if (nt > 4) nt = 4;

    float acc[TC_MT][4][4];
#pragma unroll
    for (int mi = 0; mi < TC_MT; ++mi)
#pragma unroll
        for (int j = 0; j < 4; ++j)
#pragma unroll
            for (int e = 0; e < 4; ++e) acc[mi][j][e] = 0.f;

    for (int cs = 0; cs < CI; cs += TC_SLAB) {
        const int sc = CI - cs < TC_SLAB ? CI - cs : TC_SLAB;  // 16 or 32
        const int cpp = sc / 8;                                  // 16-byte chunks a pixel
        __syncthreads();  // the previous slab's reads are done
        for (int e = threadIdx.x; e < TC_HALO_H * TC_HALO_W * cpp; e += blockDim.x) {
            const int pix = e / cpp, ch = (e - pix * cpp) * 8;
            const int hy = pix / TC_HALO_W, hx = pix - hy * TC_HALO_W;
            const int sy = tc_pad(ty0 + hy - 1, H, pad_mode), sx = tc_pad(tx0 + hx - 1, W, pad_mode);
            uint4 v = make_uint4(0u, 0u, 0u, 0u);
            if (sy >= 0 && sx >= 0) v = *(const uint4*)(xi + ((long long)sy * W + sx) * CI + cs + ch);
            *(uint4*)(As + pix * TC_A_STRIDE + ch) = v;
        }
        for (int e = threadIdx.x; e < TC_COUT * 9 * cpp; e += blockDim.x) {
            const int n = e / (9 * cpp), r = e - n * 9 * cpp, tap = r / cpp, ch = (r - tap * cpp) * 8;
            uint4 v = make_uint4(0u, 0u, 0u, 0u);
            if (n0 + n < COP) v = *(const uint4*)(w + (long long)(n0 + n) * K9 + tap * CI + cs + ch);
            *(uint4*)(Ws + n * TC_W_STRIDE + tap * TC_SLAB + ch) = v;
        }
        __syncthreads();
        for (int tap = 0; tap < 9; ++tap) {
            const int ky = tap / 3, kx = tap - (tap / 3) * 3;
            for (int c0 = 0; c0 < sc; c0 += 16) {
                unsigned a[TC_MT][4];
#pragma unroll
                for (int mi = 0; mi < TC_MT; ++mi) {
                    const unsigned short* r0 =
                        As + ((TC_MT * warp + mi + ky) * TC_HALO_W + g + kx) * TC_A_STRIDE + c0 + 2 * t;
                    const unsigned short* r1 = r0 + 8 * TC_A_STRIDE;
                    a[mi][0] = *(const unsigned*)r0;
                    a[mi][1] = *(const unsigned*)r1;
                    a[mi][2] = *(const unsigned*)(r0 + 8);
                    a[mi][3] = *(const unsigned*)(r1 + 8);
                }
#pragma unroll
                for (int j = 0; j < 4; ++j) {
                    if (j < nt) {
                        const unsigned short* wr = Ws + (j * 8 + g) * TC_W_STRIDE + tap * TC_SLAB + c0 + 2 * t;
                        unsigned bf[2];
                        bf[0] = *(const unsigned*)wr;
                        bf[1] = *(const unsigned*)(wr + 8);
#pragma unroll
                        for (int mi = 0; mi < TC_MT; ++mi) mma16816(acc[mi][j], a[mi], bf);
                    }
                }
            }
        }
    }

#pragma unroll
    for (int mi = 0; mi < TC_MT; ++mi) {
#pragma unroll
        for (int hi = 0; hi < 2; ++hi) {
            const int yy = ty0 + TC_MT * warp + mi, xx = tx0 + g + 8 * hi;
            if (yy >= H || xx >= W) continue;
            const long long q = ((long long)z * NB + img) * HW + yy * W + xx;  // pixel of (Z, NB, H, W)
#pragma unroll
            for (int j = 0; j < 4; ++j) {
                if (j >= nt) continue;
                const int o = n0 + j * 8 + 2 * t;
                float v0 = acc[mi][j][2 * hi] + b[o], v1 = acc[mi][j][2 * hi + 1] + b[o + 1];
                if (mode == 0) {
                    const long long at = q * COP + o;
                    if (skip != 0 && z < nskip) {
                        v0 += h2f(skip[at]);
                        v1 += h2f(skip[at + 1]);
                    }
                    if (relu) {
                        v0 = v0 > 0.f ? v0 : 0.f;
                        v1 = v1 > 0.f ? v1 : 0.f;
                    }
                    unsigned short* yo = (unsigned short*)y;
                    *(unsigned*)(yo + at) = (unsigned)f2h(v0) | ((unsigned)f2h(v1) << 16);
                } else if (mode == 1) {
                    const int C4 = COP / 4, H2 = 2 * H, W2 = 2 * W;
                    unsigned short* yo = (unsigned short*)y + ((long long)z * NB + img) * (4LL * HW) * C4;
                    const float vv[2] = {v0, v1};
#pragma unroll
                    for (int e = 0; e < 2; ++e) {
                        const int oc = o + e, c = oc >> 2, si = (oc >> 1) & 1, sj = oc & 1;
                        const long long at = ((long long)(2 * yy + si) * W2 + 2 * xx + sj) * C4 + c;
                        yo[at] = f2h(relu && vv[e] < 0.f ? 0.f : vv[e]);
                    }
                } else {
                    const int co = z < ng ? co_geo : co_map;
                    float* yo = (float*)y + ((long long)z * NB + img) * CO * HW + yy * W + xx;
                    if (o < co) yo[(long long)o * HW] = v0;
                    if (o + 1 < co) yo[(long long)(o + 1) * HW] = v1;
                }
            }
        }
    }
}

// The nets' outputs back onto the frames, averaged over nets z0 <= z < z1 and the V views:
//   y[n, c, yy, xx] = 1/((z1 - z0) V) sum_v sum_z f(s[z, v*N + n, c, flip_v(yy, xx)])
// s: (Z, V*N, CO, H, W) fp32 (conv3x3_tc mode 2), y: (N, C, H, W) fp32, C <= CO; f: the logistic
// sigmoid if sig, and the value negated where view v mirrored axis c (flags as in views_to_nhwc;
// only if neg). Sums run in z, then v order. 1-D grid-stride over N*C*H*W.
extern "C" __global__ void views_average(const float* __restrict__ s, float* __restrict__ y, int z0, int z1,
                                         int V, int N, int CO, int C, int H, int W, int flags, int neg,
                                         int sig) {
    const long long HW = (long long)H * W, total = (long long)N * C * HW;
    const float scale_z = 1.f / (float)(z1 - z0), scale_v = 1.f / (float)V;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < total;
         i += (long long)gridDim.x * blockDim.x) {
        const int r = (int)(i % HW);
        const int c = (int)((i / HW) % C);
        const int n = (int)(i / (HW * C));
        float sum_v = 0.f;
        for (int v = 0; v < V; ++v) {
            const int f = (flags >> (8 * v)) & 255;
            int yy = r / W, xx = r - (r / W) * W;
            if (f & 1) yy = H - 1 - yy;
            if (f & 2) xx = W - 1 - xx;
            float sum_z = 0.f;
            for (int z = z0; z < z1; ++z) {
                float val = s[(((long long)z * V * N + (long long)v * N + n) * CO + c) * HW + yy * W + xx];
                if (sig) {  // the stable form of elementwise.cu's sigmoid
                    const float e = expf(val >= 0.f ? -val : val);
                    val = val >= 0.f ? 1.f / (1.f + e) : e / (1.f + e);
                }
                sum_z += val;
            }
            sum_z *= scale_z;
            if (neg && ((f >> (2 + c)) & 1)) sum_z = -sum_z;
            sum_v += sum_z;
        }
        y[i] = sum_v * scale_v;
    }
}
