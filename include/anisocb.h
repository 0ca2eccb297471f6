/*
 * anisocb — geometry-image super-resolution of cloth animations, as a C library.
 *
 * Build: `make c-example` (or `cargo rustc --release --lib --no-default-features --features capi
 * --crate-type staticlib,cdylib`) gives target/release/libanisocb.a and libanisocb.so; link the
 * static one with -lpthread -ldl -lm.
 *
 * Use: make an upscaler (anisocb_new), give it a shot's LR frames one at a time (anisocb_push),
 * take the last held-back frames at the end (anisocb_flush), free it (anisocb_free). Frames are
 * regular grids of w x h vertices, row-major, xyz interleaved (3*w*h floats, metres); results
 * have (r*w) x (r*h) vertices (r = anisocb_scale, 2). Every buffer is the caller's. Every call
 * returns a status; on an error anisocb_last_error() says what went wrong. No call panics
 * across the boundary or aborts the host. A handle is used by one thread at a time.
 * Each frame gives the same bits as `anisocb upscale` gives it (OBJ output).
 */
#ifndef ANISOCB_H
#define ANISOCB_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum anisocb_status {
    ANISOCB_OK = 0,            /* done; a push or flush wrote a frame */
    ANISOCB_PENDING = 1,       /* push: no frame out yet (temporal context still coming) */
    ANISOCB_DONE = 2,          /* flush: no frame left; the next push starts a new shot */
    ANISOCB_ERR_ARGUMENT = -1, /* a null pointer, a short output buffer, a non-UTF-8 path */
    ANISOCB_ERR_IO = -2,       /* a file could not be read (weights_path) */
    ANISOCB_ERR_FORMAT = -3,   /* a file is malformed (weights for another architecture, ...) */
    ANISOCB_ERR_SHAPE = -4,    /* a frame's size differs from the shot's, a grid too small */
    ANISOCB_ERR_CONFIG = -5,   /* an option out of range (eta, temporal, threads, ...) */
    ANISOCB_ERR_NUMERIC = -6,  /* NaN/inf in a frame, or weights that give nonsense */
    ANISOCB_ERR_DEVICE = -7,   /* the compute device failed */
    ANISOCB_ERR_MEMORY = -8,   /* a shot's first frame needs more memory than can be had */
    ANISOCB_ERR_PANIC = -99    /* an internal error (a bug): the handle should be freed */
} anisocb_status;

/* Options; fill with anisocb_options_default, then change what you need. */
typedef struct anisocb_options {
    uint32_t threads;         /* worker threads of the upscaler's own; 0 = one per core */
    const char *weights_path; /* a weights bundle (.npz, UTF-8), or NULL for the embedded model */
    float eta;                /* wrinkle enhancement, -1 to 10 (default 0) */
    uint32_t temporal;        /* temporal smoothing radius in frames, 0 to 64 (default 0) */
    uint32_t strain_iters;    /* strain-limit iterations, 0 to 1000 (default 0) */
    int mirrors;              /* 1: average over the grid's four mirror images (default) */
    int keep_outline;         /* 1: the border never shorter than the LR one (default) */
    int pin_border;           /* 1: outermost ring where interpolation puts it (default 0) */
    int gate_coarse_only;     /* 1: BoundaryNet gates only the coarse detail (default 0) */
    /* The physics pass (`anisocb upscale --physics`, docs/research/wrinkles.md): an HR cloth held to the
     * frames at the LR grid's scale adds the folds an HR simulation forms. Frames are read as
     * metres; a shot starts at its first frame and ends with anisocb_flush. With it a frame
     * allocates (the simulation's buffers). */
    int physics;              /* 1: on (default 0) */
    float gravity[3];         /* m/s2 in the shot's axes (default 0, -9.81, 0: y-up) */
    float fps;                /* the shot's frame rate (default 30) */
    const char *material;     /* silk, cotton, denim, rubber (UTF-8); NULL: cotton */
    const char *physics_pin;  /* held edges, e.g. "top" or "left,right" (UTF-8); NULL: none */
    float physics_drift;      /* s over which the cloth's drift from the shot is taken out
                               * (default 3; INFINITY: never) */
    float physics_ground;     /* a floor's height (m) along -gravity; NAN (default): none */
    float physics_sphere[4];  /* a static sphere: centre x, y, z and radius (m); r = 0: none */
    float physics_box[6];     /* a static axis-aligned box: centre, half extents (m); 0: none */
    uint64_t memory_limit_mib; /* the most MiB a shot's frames may take; 0 (default): what the
                                * allocator gives. A shot's first frame that needs more returns
                                * ANISOCB_ERR_MEMORY (never an abort of the host) */
} anisocb_options;

typedef struct Upscaler anisocb_upscaler; /* opaque */

/* The message of the last failed call on this thread ("" if none), valid until the next call. */
const char *anisocb_last_error(void);
/* The library version, e.g. "0.1.0". */
const char *anisocb_version(void);

int anisocb_options_default(anisocb_options *opts);
/* opts may be NULL (defaults). On success *out is a handle to free with anisocb_free. */
int anisocb_new(const anisocb_options *opts, anisocb_upscaler **out);
void anisocb_free(anisocb_upscaler *up);
/* The scale r (2), and the frames a result lags its input (the temporal radius). */
uint32_t anisocb_scale(const anisocb_upscaler *up);
uint32_t anisocb_latency(const anisocb_upscaler *up);

/* Give the next LR frame (3*w*h floats). Writes the next HR frame into hr (hr_cap floats, at
 * least 3*r*w*r*h) and returns ANISOCB_OK, or returns ANISOCB_PENDING. It allocates no heap
 * memory after a shot's first few frames. A shot's first frame first asks the allocator, in a
 * way that can fail, for about the memory its frames take (or holds to memory_limit_mib), and
 * returns ANISOCB_ERR_MEMORY where it cannot be had; the frames after it then fit. Memory that
 * another part of the host takes after that check can still run out inside a later call. */
int anisocb_push(anisocb_upscaler *up, uint32_t w, uint32_t h, const float *lr, float *hr,
                 size_t hr_cap);
/* At the end of a shot: writes the next held-back HR frame and returns ANISOCB_OK, or returns
 * ANISOCB_DONE when none is left. Grids and meshes (anisocb_set_mesh) alike. */
int anisocb_flush(anisocb_upscaler *up, float *hr, size_t hr_cap);

/* Any mesh, not only a grid (a garment, a disk, a sheet with a hole): n_vertices vertices at
 * rest (3*n_vertices floats, metres), n_faces faces of face_sizes[i] (3 or 4) vertex indices
 * each, concatenated in indices (0-based). Its UVs lay it out where they are a usable layout:
 * n_uv coordinates (uv: 2*n_uv floats) and each face corner's index into them (uv_indices, laid
 * out like indices); uv = NULL: an ARAP layout. Call between shots; frames then go in through
 * anisocb_push_mesh. */
int anisocb_set_mesh(anisocb_upscaler *up, uint32_t n_vertices, const float *rest, uint32_t n_faces,
                     const uint32_t *face_sizes, const uint32_t *indices, uint32_t n_uv,
                     const float *uv, const uint32_t *uv_indices);
/* The HR mesh: its vertex count (0 without a mesh), and its faces, 4 per LR face in its order
 * (a triangle into 4 triangles, a quad into 4 quads): sizes into face_sizes, vertex indices
 * concatenated into indices. */
uint32_t anisocb_hr_vertex_count(const anisocb_upscaler *up);
int anisocb_hr_faces(const anisocb_upscaler *up, uint32_t *face_sizes, size_t sizes_cap,
                     uint32_t *indices, size_t indices_cap);
/* anisocb_push for the mesh: the next LR frame (3*n_vertices floats, the mesh's vertex order);
 * writes the next HR frame (3*anisocb_hr_vertex_count floats) and returns ANISOCB_OK, or returns
 * ANISOCB_PENDING. */
int anisocb_push_mesh(anisocb_upscaler *up, const float *lr, float *hr, size_t hr_cap);

#ifdef __cplusplus
}
#endif
#endif /* ANISOCB_H */
