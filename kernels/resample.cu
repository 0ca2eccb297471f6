// resample.cu - align-corners resize (bilinear or bicubic), forward and backward, both as
// gathers: the per-axis taps (source index + weight of each output index, clamped at the
// border) are computed on the host exactly as the CPU path computes them
// (anisocb::cuda::taps), so the GPU only sums. Contract: anisocb::ops::resample::{resize_ref,
// resize_backward_ref}. No atomics: results are reproducible bit for bit.

// Forward. x: (NC, Hi, Wi) -> y: (NC, Ho, Wo).
//   y[p, oy, ox] = sum_a ty_w[oy*Ky + a] * (sum_b tx_w[ox*Kx + b] * x[p, ty_i[oy*Ky + a], tx_i[ox*Kx + b]])
// (interpolate along x in each source row, then along y: the reference's order.)
// Ky, Kx: taps per output index (2 bilinear, 4 bicubic). 1-D grid-stride over NC*Ho*Wo.
extern "C" __global__ void resize_fwd(const float* __restrict__ x, float* __restrict__ y,
                                      long long NC, int Hi, int Wi, int Ho, int Wo,
                                      const int* __restrict__ ty_i, const float* __restrict__ ty_w, int Ky,
                                      const int* __restrict__ tx_i, const float* __restrict__ tx_w, int Kx) {
    const long long total = NC * Ho * Wo;
    for (long long e = (long long)blockIdx.x * blockDim.x + threadIdx.x; e < total;
         e += (long long)gridDim.x * blockDim.x) {
        const int ox = (int)(e % Wo);
        const int oy = (int)((e / Wo) % Ho);
        const long long p = e / ((long long)Wo * Ho);
        const float* src = x + p * Hi * Wi;
        float acc = 0.f;
        for (int a = 0; a < Ky; ++a) {
            const float* row = src + (long long)ty_i[oy * Ky + a] * Wi;
            float s = 0.f;
            for (int b = 0; b < Kx; ++b) s += tx_w[ox * Kx + b] * row[tx_i[ox * Kx + b]];
            acc += ty_w[oy * Ky + a] * s;
        }
        y[e] = acc;
    }
}

// Backward (adjoint), gather form over transposed taps in CSR layout: for source index i along
// an axis, entries cy_ptr[i] .. cy_ptr[i + 1] of (cy_o, cy_w) list the output indices that read
// it and the (merged) weights. dy: (NC, Ho, Wo); dx: (NC, Hi, Wi), ADDED into.
//   dx[p, iy, ix] += sum_{(oy, wy) in col_y(iy)} wy * sum_{(ox, wx) in col_x(ix)} wx * dy[p, oy, ox]
// 1-D grid-stride over NC*Hi*Wi.
extern "C" __global__ void resize_bwd(const float* __restrict__ dy, float* __restrict__ dx,
                                      long long NC, int Hi, int Wi, int Ho, int Wo,
                                      const int* __restrict__ cy_ptr, const int* __restrict__ cy_o,
                                      const float* __restrict__ cy_w,
                                      const int* __restrict__ cx_ptr, const int* __restrict__ cx_o,
                                      const float* __restrict__ cx_w) {
    const long long total = NC * Hi * Wi;
    for (long long e = (long long)blockIdx.x * blockDim.x + threadIdx.x; e < total;
         e += (long long)gridDim.x * blockDim.x) {
        const int ix = (int)(e % Wi);
        const int iy = (int)((e / Wi) % Hi);
        const long long p = e / ((long long)Wi * Hi);
        const float* g = dy + p * Ho * Wo;
        float acc = 0.f;
        for (int a = cy_ptr[iy]; a < cy_ptr[iy + 1]; ++a) {
            const float* row = g + (long long)cy_o[a] * Wo;
            float s = 0.f;
            for (int b = cx_ptr[ix]; b < cx_ptr[ix + 1]; ++b) s += cx_w[b] * row[cx_o[b]];
            acc += cy_w[a] * s;
        }
        dx[e] += acc;
    }
}
