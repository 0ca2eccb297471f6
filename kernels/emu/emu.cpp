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
EXPORT(conv2d_wgrad)
EXPORT(conv2d_wgrad_reduce)
EXPORT(conv2d_dgrad_padded)
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
EXPORT(adam_step)
