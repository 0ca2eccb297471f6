// loss.cu - mean losses with their gradients, any shape (flat, n elements). Contract:
// anisocb::ops::loss::{mse_ref, bce_with_logits_ref}: per-element gradients use the reference's
// expressions; the loss is accumulated in double per thread, reduced in a fixed tree per block
// into part[blockIdx.x], and the host adds the block partials in order (reproducible bits).
// Launch with blockDim.x = 256 (the shared reduction buffer size, a power of two).

#define RED 256

__device__ __forceinline__ void block_sum_to(double s, double* part) {
    __shared__ double red[RED];
    red[threadIdx.x] = s;
    __syncthreads();
    for (int h = RED / 2; h > 0; h >>= 1) {
        if ((int)threadIdx.x < h) red[threadIdx.x] += red[threadIdx.x + h];
        __syncthreads();
    }
    if (threadIdx.x == 0) part[blockIdx.x] = red[0];
}

// d = p - t;  grad = 2*d / nf;  part[block] = sum d^2 (double). nf = max(n, 1) as float.
extern "C" __global__ void mse_loss(const float* __restrict__ pred, const float* __restrict__ target,
                                    float* __restrict__ grad, double* __restrict__ part,
                                    long long n, float nf) {
    double s = 0.0;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n;
         i += (long long)gridDim.x * blockDim.x) {
        const float d = pred[i] - target[i];
        s += (double)d * (double)d;
        grad[i] = 2.f * d / nf;
    }
    block_sum_to(s, part);
}

__device__ __forceinline__ float sigmoid1(float z) {
    if (z >= 0.f) return 1.f / (1.f + expf(-z));
    const float e = expf(z);
    return e / (1.f + e);
}

// softplus(z) = log(1 + e^z) without overflow.
__device__ __forceinline__ float softplus(float z) { return fmaxf(z, 0.f) + log1pf(expf(-fabsf(z))); }

// loss_i = w*t*softplus(-z) + (1-t)*softplus(z);  grad_i = (w*t*(sigmoid(z) - 1) + (1-t)*sigmoid(z)) / nf;
// part[block] = sum loss_i (double). w = pos_weight.
extern "C" __global__ void bce_logits_loss(const float* __restrict__ z, const float* __restrict__ target,
                                           float* __restrict__ grad, double* __restrict__ part,
                                           long long n, float nf, float pos_weight) {
    double s = 0.0;
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n;
         i += (long long)gridDim.x * blockDim.x) {
        const float zi = z[i], t = target[i];
        const float wt = pos_weight * t;
        const float l = wt * softplus(-zi) + (1.f - t) * softplus(zi);
        const float sg = sigmoid1(zi);
        s += (double)l;
        grad[i] = (wt * (sg - 1.f) + (1.f - t) * sg) / nf;
    }
    block_sum_to(s, part);
}

// GeometryNet's loss on the device (anisocb::nn::geometry_net::estimate_loss with the Laplacian
// and wrinkle-energy weights 0): MSE + we * edge_mse + wl * edge_length_mse of est (N, C, H, W)
// against target, and its gradient. One thread per pixel (n, y, x), all C channels. Each term's
// gradient at a pixel is gathered from the grid edges that touch it in the order the CPU's
// scatter adds them (the edge from the pixel above, from the left, to the right, downwards:
// + at an edge's end, - at its start), and the terms are added as estimate_loss adds them, so
// with fmad off the gradient has the CPU's bits. A term with weight 0 is skipped, as there.
//   mse:    d = est - target;  g = 2 d / nf
//   edge:   e = d[end] - d[start] per channel;  g_e = sum(+-2 e / edge_count)
//   length: e = |P[end] - P[start]| - |T[end] - T[start]| over the C channels of a pixel;
//           g_l = sum(+-k (P[end] - P[start])), k = len_scale * e / |P[end] - P[start]|,
//           no gradient from an edge of zero length (len_scale = 2 / length count)
// part[b], part[G + b], part[2G + b] (G = gridDim.x): block b's f64 sums of d^2, of the edge
// errors^2 and of the length errors^2 (each edge counted at its start; 0 for a term of weight 0).
extern "C" __global__ void geometry_loss(const float* __restrict__ est, const float* __restrict__ target,
                                         float* __restrict__ grad, double* __restrict__ part,
                                         int N, int C, int H, int W, float nf, float edge_count,
                                         float len_scale, float we, float wl) {
    const long long HW = (long long)H * W, P = (long long)N * HW;
    double s_mse = 0.0, s_edge = 0.0, s_len = 0.0;
    for (long long q = (long long)blockIdx.x * blockDim.x + threadIdx.x; q < P;
         q += (long long)gridDim.x * blockDim.x) {
        const long long img = q / HW;
        const int r = (int)(q - img * HW), y = r / W, x = r - y * W;
        const long long base = img * C * HW + r;  // channel 0 of this pixel
        // The four edges at this pixel: up, left (ending here), right, down (starting here).
        const bool has[4] = {y > 0, x > 0, x + 1 < W, y + 1 < H};
        const long long off[4] = {-(long long)W, -1, 1, (long long)W};
        float k[4] = {0.f, 0.f, 0.f, 0.f};
        bool k_on[4] = {false, false, false, false};
        if (wl != 0.f) {
            for (int e = 0; e < 4; ++e) {
                if (!has[e]) continue;
                const long long a = e < 2 ? base + off[e] : base, b = e < 2 ? base : base + off[e];
                float sp = 0.f, st = 0.f;
                for (int ch = 0; ch < C; ++ch) {
                    const float dp = est[b + ch * HW] - est[a + ch * HW];
                    const float dt = target[b + ch * HW] - target[a + ch * HW];
                    sp = sp + dp * dp;
                    st = st + dt * dt;
                }
                const float lp = sqrtf(sp), el = lp - sqrtf(st);
                if (e >= 2) s_len += (double)el * (double)el;
                if (lp > 0.f) {
                    k[e] = len_scale * el / lp;
                    k_on[e] = true;
                }
            }
        }
        for (int ch = 0; ch < C; ++ch) {
            const long long i = base + ch * HW;
            const float d = est[i] - target[i];
            s_mse += (double)d * (double)d;
            float g = 2.f * d / nf;
            if (we != 0.f) {
                float ge = 0.f;
                for (int e = 0; e < 4; ++e) {
                    if (!has[e]) continue;
                    const float dn = est[i + off[e]] - target[i + off[e]];
                    const float ee = e < 2 ? d - dn : dn - d;  // end minus start
                    const float gee = 2.f * ee / edge_count;
                    ge = e < 2 ? ge + gee : ge - gee;
                    if (e >= 2) s_edge += (double)ee * (double)ee;
                }
                g = g + we * ge;
            }
            if (wl != 0.f) {
                float gl = 0.f;
                for (int e = 0; e < 4; ++e) {
                    if (!k_on[e]) continue;
                    const float dd = k[e] * (e < 2 ? est[i] - est[i + off[e]] : est[i + off[e]] - est[i]);
                    gl = e < 2 ? gl + dd : gl - dd;
                }
                g = g + wl * gl;
            }
            grad[i] = g;
        }
    }
    block_sum_to(s_mse, part);
    block_sum_to(s_edge, part + gridDim.x);
    block_sum_to(s_len, part + 2 * gridDim.x);
}
