// adam.cu - one Adam step with bias correction (optax's form, eps outside the square root).
// Contract: anisocb::ops::adam::adam_update_ref, same per-element expression; c1 = 1 - beta1^t
// and c2 = 1 - beta2^t are computed on the host (f64, rounded once).
//   m <- (1-beta1)*g + beta1*m,  v <- (1-beta2)*g^2 + beta2*v,  p <- p - lr * ((m / c1) / (sqrt(v / c2) + eps))

__device__ __forceinline__ void adam1(float* __restrict__ p, const float* __restrict__ g,
                                      float* __restrict__ m, float* __restrict__ v, long long i,
                                      float lr, float b1, float b2, float eps, float c1, float c2) {
    const float gi = g[i];
    const float mi = (1.f - b1) * gi + b1 * m[i];
    const float vi = (1.f - b2) * (gi * gi) + b2 * v[i];
    m[i] = mi;
    v[i] = vi;
    p[i] -= lr * ((mi / c1) / (sqrtf(vi / c2) + eps));
}

// One flat parameter buffer of n values. 1-D grid-stride over n.
extern "C" __global__ void adam_step(float* __restrict__ p, const float* __restrict__ g,
                                     float* __restrict__ m, float* __restrict__ v, long long n,
                                     float lr, float b1, float b2, float eps, float c1, float c2) {
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n;
         i += (long long)gridDim.x * blockDim.x)
        adam1(p, g, m, v, i, lr, b1, b2, eps, c1, c2);
}

// Every parameter tensor of a trunk in one launch (device-resident training), each gradient
// zeroed once read, ready for the next step's backward to add into. table: one row of 5 values
// per tensor, (p, g, m, v) device addresses and n. grid (x, tensors): blockIdx.y the tensor,
// a grid-stride loop over its n on gridDim.x blocks. Each element gets adam_step's bits.
extern "C" __global__ void adam_step_all(const unsigned long long* __restrict__ table, float lr,
                                         float b1, float b2, float eps, float c1, float c2) {
    const unsigned long long* row = table + 5ull * blockIdx.y;
    float* p = (float*)row[0];
    float* g = (float*)row[1];
    float* m = (float*)row[2];
    float* v = (float*)row[3];
    const long long n = (long long)row[4];
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n;
         i += (long long)gridDim.x * blockDim.x) {
        adam1(p, g, m, v, i, lr, b1, b2, eps, c1, c2);
        g[i] = 0.f;
    }
}
