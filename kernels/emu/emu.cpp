// emu.cpp — run kernels/*.cu on the CPU, for checking kernel index math on machines without a
// GPU (kernels/emu/check_kernels.py drives it). Each launch runs the grid's blocks one after
// another on blockDim.x real threads; __syncthreads is a barrier, __shared__ is a static
// (shared by the block's threads). Launch arguments come as an array of pointers to the values,
// like cuLaunchKernel's kernelParams. Build: g++ -O1 -std=c++20 -shared -fPIC -pthread emu.cpp
#include <barrier>
#include <cmath>
#include <cstddef>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>
#include <algorithm>

struct dim3 {
    unsigned x = 1, y = 1, z = 1;
};
static thread_local dim3 threadIdx, blockIdx;
static dim3 blockDim, gridDim;
static std::barrier<>* g_bar = nullptr;
static inline void __syncthreads() { g_bar->arrive_and_wait(); }
using std::max;
using std::min;

#define __global__
#define __device__
#define __forceinline__ inline
#define __restrict__ __restrict
#define __shared__ static

#include "../conv2d.cu"
#include "../elementwise.cu"
#include "../pixel_shuffle.cu"
#include "../resample.cu"
#undef RED
#define block_sum_to block_sum_to_loss
#define sigmoid1 sigmoid1_loss
#include "../loss.cu"
#include "../adam.cu"

// infer.cu's warp-level pieces: fp16 conversions through _Float16 (round to nearest even, as
// cvt.rn.f16.f32) and mma.sync m16n8k16 as a warp exchange through static arrays between two
// block barriers (every thread of a block calls it equally often: infer.cu's loops are uniform).
#include <cstring>
#define ANISOCB_EMU
#define __align__(n) __attribute__((aligned(n)))
struct uint4 {
    unsigned x, y, z, w;
};
static inline uint4 make_uint4(unsigned a, unsigned b, unsigned c, unsigned d) { return {a, b, c, d}; }
static unsigned short f2h(float x) {
    _Float16 h = (_Float16)x;
    unsigned short u;
    std::memcpy(&u, &h, 2);
    return u;
}
static float h2f(unsigned short u) {
    _Float16 h;
    std::memcpy(&h, &u, 2);
    return (float)h;
}
static unsigned g_mma_a[32][32][4], g_mma_b[32][32][2];
static float half_of(unsigned r, int k) { return h2f((unsigned short)(k & 1 ? r >> 16 : r & 0xffff)); }
static void mma16816(float* d, const unsigned* a, const unsigned* b) {
    const int lane = threadIdx.x & 31, wp = threadIdx.x >> 5, g = lane >> 2, t = lane & 3;
    for (int i = 0; i < 4; ++i) g_mma_a[wp][lane][i] = a[i];
    for (int i = 0; i < 2; ++i) g_mma_b[wp][lane][i] = b[i];
    __syncthreads();
    for (int e = 0; e < 4; ++e) {
        const int row = g + 8 * (e >> 1), col = 2 * t + (e & 1);
        float s = 0.f;
        for (int k = 0; k < 16; ++k) {
            const float av = half_of(g_mma_a[wp][(row % 8) * 4 + (k % 8) / 2][(row >= 8) + 2 * (k >= 8)], k);
            const float bv = half_of(g_mma_b[wp][col * 4 + (k % 8) / 2][k >= 8], k);
            s += av * bv;
        }
        d[e] += s;
    }
    __syncthreads();
}
#include "../infer.cu"

template <class F>
static void launch(unsigned gx, unsigned gy, unsigned gz, unsigned bx, F f) {
    gridDim = {gx, gy, gz};
    blockDim = {bx, 1, 1};
    std::barrier<> bar((std::ptrdiff_t)bx);
    g_bar = &bar;
    std::vector<std::thread> ts;
    for (unsigned t = 0; t < bx; ++t) {
        ts.emplace_back([&, t] {
            threadIdx = {t, 0, 0};
            for (unsigned z = 0; z < gz; ++z)
                for (unsigned y = 0; y < gy; ++y)
                    for (unsigned x = 0; x < gx; ++x) {
                        blockIdx = {x, y, z};
                        f();
                        bar.arrive_and_wait();  // the block's shared memory is reused next
                    }
        });
    }
    for (auto& t : ts) t.join();
}

template <class... A, std::size_t... I>
static void call_with(void (*k)(A...), void** args, std::index_sequence<I...>) {
    k(*static_cast<std::remove_cv_t<std::remove_reference_t<A>>*>(args[I])...);
}

template <class... A>
static void run(void (*k)(A...), unsigned gx, unsigned gy, unsigned gz, unsigned bx, void** args) {
    launch(gx, gy, gz, bx, [&] { call_with(k, args, std::index_sequence_for<A...>{}); });
}

#define EXPORT(name) \
    extern "C" void emu_##name(unsigned gx, unsigned gy, unsigned gz, unsigned bx, void** args) { \
        run(name, gx, gy, gz, bx, args); \
    }

EXPORT(conv2d_fwd)
EXPORT(conv2d_fwd_m32)
EXPORT(conv2d_wgrad)
EXPORT(conv2d_wgrad_m32)
EXPORT(conv2d_wgrad_reduce)
EXPORT(conv2d_dgrad_padded)
EXPORT(conv2d_dgrad_padded_m32)
EXPORT(conv2d_dgrad_fold)
EXPORT(conv2d_bias_grad)
EXPORT(relu_fwd)
EXPORT(relu_bwd)
EXPORT(add_assign)
EXPORT(sigmoid_fwd)
EXPORT(pixel_shuffle)
EXPORT(pixel_unshuffle)
EXPORT(resize_fwd)
EXPORT(resize_bwd)
EXPORT(mse_loss)
EXPORT(bce_logits_loss)
EXPORT(geometry_loss)
EXPORT(adam_step)
EXPORT(adam_step_all)
EXPORT(f32_to_f16)
EXPORT(views_to_nhwc)
EXPORT(conv3x3_tc)
EXPORT(views_average)
