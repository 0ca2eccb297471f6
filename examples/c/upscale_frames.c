/*
 * Upscale an OBJ sequence through the C ABI and check every HR frame against the files
 * `anisocb upscale` wrote for the same frames, bit for bit.
 *
 *   upscale_frames LR_DIR CLI_HR_DIR FRAMES [TEMPORAL [PINS]]
 *
 * LR_DIR holds frame_0000.obj ... (regular grids whose first line is the simulator's
 * "# anisocb grid W x H" comment, vertices row-major); CLI_HR_DIR holds what
 * `anisocb upscale LR_DIR --out CLI_HR_DIR [--temporal TEMPORAL]` wrote (with PINS, the physics
 * pass with those held edges: `--physics --physics-pin PINS`). Exit status 0 when all FRAMES
 * frames match. `make c-example` builds and runs it on the demo's frames.
 */
#include "anisocb.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The `v` lines of an OBJ file into a new array of 3*n floats (n returned); grid size from the
 * "# anisocb grid W x H" comment if w/h are not NULL. */
static float *read_vertices(const char *path, size_t *n, unsigned *w, unsigned *h) {
    FILE *f = fopen(path, "r");
    if (!f) {
        fprintf(stderr, "%s: cannot open\n", path);
        return NULL;
    }
    size_t cap = 4096, len = 0;
    float *v = malloc(cap * sizeof(float));
    char line[512];
    while (v && fgets(line, sizeof line, f)) {
        if (w && h && sscanf(line, "# anisocb grid %u x %u", w, h) == 2) continue;
        if (line[0] != 'v' || line[1] != ' ') continue;
        if (len + 3 > cap) {
            cap *= 2;
            float *grown = realloc(v, cap * sizeof(float));
            if (!grown) { free(v); v = NULL; break; }
            v = grown;
        }
        char *p = line + 2;
        for (int k = 0; k < 3; k++) v[len++] = strtof(p, &p);
    }
    fclose(f);
    *n = len / 3;
    return v;
}

/* Compare an HR frame with the CLI's file for frame k; 1 when bit-identical. */
static int same_as_cli(const char *hr_dir, int k, const float *hr, size_t n) {
    char path[4096];
    snprintf(path, sizeof path, "%s/frame_%04d.obj", hr_dir, k);
    size_t m = 0;
    float *cli = read_vertices(path, &m, NULL, NULL);
    int same = cli && m == n && memcmp(cli, hr, 3 * n * sizeof(float)) == 0;
    if (!same) fprintf(stderr, "frame %d differs from %s\n", k, path);
    free(cli);
    return same;
}

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: %s LR_DIR CLI_HR_DIR FRAMES [TEMPORAL [PINS]]\n", argv[0]);
        return 2;
    }
    const char *lr_dir = argv[1], *hr_dir = argv[2];
    int frames = atoi(argv[3]);
    anisocb_options opts;
    anisocb_options_default(&opts);
    if (argc > 4) opts.temporal = (uint32_t)atoi(argv[4]);
    if (argc > 5) {
        opts.physics = 1;
        opts.physics_pin = argv[5];
    }
    anisocb_upscaler *up = NULL;
    if (anisocb_new(&opts, &up) != ANISOCB_OK) {
        fprintf(stderr, "anisocb_new: %s\n", anisocb_last_error());
        return 1;
    }
    unsigned r = anisocb_scale(up), w = 0, h = 0;
    float *hr = NULL;
    size_t hr_cap = 0;
    int out = 0, bad = 0;
    for (int k = 0; k < frames; k++) {
        char path[4096];
        snprintf(path, sizeof path, "%s/frame_%04d.obj", lr_dir, k);
        size_t n = 0;
        float *lr = read_vertices(path, &n, &w, &h);
        if (!lr || n != (size_t)w * h) {
            fprintf(stderr, "%s: expected a %u x %u grid, read %zu vertices\n", path, w, h, n);
            return 1;
        }
        if (!hr) {
            hr_cap = 3 * (size_t)r * w * r * h;
            hr = malloc(hr_cap * sizeof(float));
        }
        int s = anisocb_push(up, w, h, lr, hr, hr_cap);
        free(lr);
        if (s < 0) {
            fprintf(stderr, "anisocb_push (frame %d): %s\n", k, anisocb_last_error());
            return 1;
        }
        if (s == ANISOCB_OK) bad += !same_as_cli(hr_dir, out++, hr, hr_cap / 3);
    }
    int s;
    while ((s = anisocb_flush(up, hr, hr_cap)) == ANISOCB_OK) bad += !same_as_cli(hr_dir, out++, hr, hr_cap / 3);
    if (s != ANISOCB_DONE) {
        fprintf(stderr, "anisocb_flush: %s\n", anisocb_last_error());
        return 1;
    }
    /* A wrong call answers with a status and a message, not a crash. */
    if (anisocb_push(up, w, h, NULL, hr, hr_cap) != ANISOCB_ERR_ARGUMENT || !*anisocb_last_error()) {
        fprintf(stderr, "a null frame was not refused\n");
        return 1;
    }
    anisocb_free(up);
    free(hr);
    printf("C ABI (anisocb %s): %d of %d frames %ux%u -> %ux%u, %d differ from `anisocb upscale`%s\n",
           anisocb_version(), out, frames, w, h, r * w, r * h, bad, bad ? "" : " (bit-identical)");
    return bad || out != frames;
}
