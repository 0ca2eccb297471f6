// adam.cu - one Adam step with bias correction on a flat parameter buffer (optax's form, eps
// outside the square root). Contract: anisocb::ops::adam::adam_update_ref, same per-element
// expression; c1 = 1 - beta1^t and c2 = 1 - beta2^t are computed on the host (f64, rounded once).
//   m <- (1-beta1)*g + beta1*m,  v <- (1-beta2)*g^2 + beta2*v,  p <- p - lr * ((m / c1) / (sqrt(v / c2) + eps))
// 1-D grid-stride over n.
extern "C" __global__ void adam_step(float* __restrict__ p, const float* __restrict__ g,
                                     float* __restrict__ m, float* __restrict__ v, long long n,
                                     float lr, float b1, float b2, float eps, float c1, float c2) {
    for (long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x; i < n;
         i += (long long)gridDim.x * blockDim.x) {
        const float gi = g[i];
        const float mi = (1.f - b1) * gi + b1 * m[i];
        const float vi = (1.f - b2) * (gi * gi) + b2 * v[i];
        m[i] = mi;
        v[i] = vi;
        p[i] -= lr * ((mi / c1) / (sqrtf(vi / c2) + eps));
    }
}
