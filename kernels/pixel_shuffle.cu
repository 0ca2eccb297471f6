// pixel_shuffle.cu - sub-pixel rearrangement, PyTorch's channel order. Both directions are
// gathers (each output element read from exactly one input element). Contract:
// anisocb::ops::pixel_shuffle::{pixel_shuffle_ref, pixel_unshuffle_ref}.

// x: (N, C*r^2, H, W) -> y: (N, C, H*r, W*r);  y[n, c, h*r + i, w*r + j] = x[n, c*r^2 + i*r + j, h, w].
// C is the OUTPUT channel count. 1-D grid-stride over the N*C*H*r*W*r outputs.
extern "C" __global__ void pixel_shuffle(const float* __restrict__ x, float* __restrict__ y,
                                         int N, int C, int H, int W, int r) {
    const int Ho = H * r, Wo = W * r;
    const long long total = (long long)N * C * Ho * Wo;
    for (long long e = (long long)blockIdx.x * blockDim.x + threadIdx.x; e < total;
         e += (long long)gridDim.x * blockDim.x) {
        const int xo = (int)(e % Wo);
        const int yo = (int)((e / Wo) % Ho);
        const long long nc = e / ((long long)Wo * Ho);  // n*C + c
        const int c = (int)(nc % C);
        const long long n = nc / C;
        const int h = yo / r, i = yo - h * r;
        const int w = xo / r, j = xo - w * r;
        const long long ci = (long long)c * r * r + i * r + j;
        y[e] = x[((n * C * r * r + ci) * H + h) * W + w];
    }
}

// x: (N, C, H*r, W*r) -> y: (N, C*r^2, H, W);  y[n, c*r^2 + i*r + j, h, w] = x[n, c, h*r + i, w*r + j].
// C is the INPUT channel count, H and W the OUTPUT size. 1-D grid-stride over the outputs.
extern "C" __global__ void pixel_unshuffle(const float* __restrict__ x, float* __restrict__ y,
                                           int N, int C, int H, int W, int r) {
    const int Cr = C * r * r;
    const long long total = (long long)N * Cr * H * W;
    for (long long e = (long long)blockIdx.x * blockDim.x + threadIdx.x; e < total;
         e += (long long)gridDim.x * blockDim.x) {
        const int w = (int)(e % W);
        const int h = (int)((e / W) % H);
        const long long nco = e / ((long long)W * H);  // n*C*r^2 + co
        const int co = (int)(nco % Cr);
        const long long n = nco / Cr;
        const int c = co / (r * r);
        const int rem = co - c * r * r;
        const int i = rem / r, j = rem - (rem / r) * r;
        y[e] = x[((n * C + c) * (long long)(H * r) + (h * r + i)) * (long long)(W * r) + (w * r + j)];
    }
}
