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
