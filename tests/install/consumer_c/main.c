/* A C99 program that uses libdsm only through its C API (dsm/dsm_c.h).
 *
 *   dsm_consumer_c MAP POINTS            writes 1,000 light-space points on and
 *                                        around the map's surfaces to POINTS
 *   dsm_consumer_c MAP POINTS EXPECTED   looks the points up in one batch and
 *                                        compares with EXPECTED, the output of
 *                                        `dsm-lookup MAP --space light
 *                                        --error-bound --input POINTS`
 *
 * Exit status 0 when everything matches, 1 otherwise. */
#include <dsm/dsm_c.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { POINT_COUNT = 1000 };

/* Prints the failure of a libdsm call and returns 1 (the exit status). */
static int report(const char* what, dsm_result result) {
    fprintf(stderr, "dsm_consumer_c: %s: %s: %s\n", what, dsm_result_name(result), dsm_last_error_message());
    return 1;
}

/* A deterministic sequence in [0, 1). */
static double next_unit(uint64_t* state) {
    *state = *state * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*state >> 11) / 9007199254740992.0;
}

/* Light-space point of raster position (rx, ry) at light depth z (see dsm_map_info). */
static void raster_to_light(const dsm_map_info* info, double rx, double ry, double z, double out[3]) {
    const double* w = info->screen_window;
    const double sx = w[0] + rx / info->width * (w[1] - w[0]);
    const double sy = w[3] - ry / info->height * (w[3] - w[2]);
    const double scale = info->projection == DSM_PROJECTION_PERSPECTIVE ? z : 1.0;
    out[0] = sx * scale;
    out[1] = sy * scale;
    out[2] = z;
}

/* Points spread over the raster, at depths before, inside and beyond the depth
 * range of the pixel they fall in, so that some are lit and some shadowed. */
static int make_points(const dsm_map* map, const dsm_map_info* info, double* points) {
    uint64_t state = 12345;
    for (int i = 0; i < POINT_COUNT; ++i) {
        const double rx = next_unit(&state) * info->width, ry = next_unit(&state) * info->height;
        dsm_pixel* pixel = NULL;
        dsm_pixel_function f = DSM_PIXEL_FUNCTION_INIT;
        dsm_result r = dsm_map_get_pixel(map, 0, (uint32_t)rx, (uint32_t)ry, &pixel);
        if (r == DSM_OK) r = dsm_pixel_get_function(pixel, &f);
        if (r != DSM_OK) {
            dsm_pixel_release(pixel);
            return report("dsm_map_get_pixel", r);
        }
        double zmin = info->near_plane + 1.0, zmax = zmin + 1.0;
        if (f.vertex_count > 0) {
            zmin = f.z[0];
            zmax = f.z[f.vertex_count - 1];
        }
        const double z = 0.5 * zmin + next_unit(&state) * (1.5 * zmax - 0.5 * zmin);
        dsm_pixel_release(pixel);
        raster_to_light(info, rx, ry, z, points + 3 * i);
    }
    return 0;
}

static int write_points(const char* path, const double* points) {
    FILE* out = fopen(path, "w");
    if (!out) {
        fprintf(stderr, "dsm_consumer_c: cannot write '%s'\n", path);
        return 1;
    }
    for (int i = 0; i < POINT_COUNT; ++i)
        fprintf(out, "%.17g %.17g %.17g\n", points[3 * i], points[3 * i + 1], points[3 * i + 2]);
    return fclose(out) == 0 ? 0 : 1;
}

static int read_points(const char* path, double* points) {
    FILE* in = fopen(path, "r");
    int n = 0;
    if (!in) {
        fprintf(stderr, "dsm_consumer_c: cannot read '%s'\n", path);
        return 1;
    }
    while (n < POINT_COUNT && fscanf(in, "%lf %lf %lf", &points[3 * n], &points[3 * n + 1], &points[3 * n + 2]) == 3)
        ++n;
    fclose(in);
    if (n != POINT_COUNT) {
        fprintf(stderr, "dsm_consumer_c: '%s' holds %d points, not %d\n", path, n, POINT_COUNT);
        return 1;
    }
    return 0;
}

/* Compares our answers with dsm-lookup's CSV lines ("v,e" or "r,g,b,e"),
 * printed the way dsm-lookup prints them (%.9g): they must be identical. */
static int compare(const char* path, int channels, const double* visibility, const double* bounds) {
    FILE* in = fopen(path, "r");
    char line[256], mine[256];
    int n = 0, shadowed = 0, lit = 0;
    if (!in) {
        fprintf(stderr, "dsm_consumer_c: cannot read '%s'\n", path);
        return 1;
    }
    while (n < POINT_COUNT && fgets(line, sizeof line, in)) {
        const double* v = visibility + 3 * n;
        line[strcspn(line, "\r\n")] = '\0';
        if (channels == 1)
            snprintf(mine, sizeof mine, "%.9g,%.9g", v[0], bounds[n]);
        else
            snprintf(mine, sizeof mine, "%.9g,%.9g,%.9g,%.9g", v[0], v[1], v[2], bounds[n]);
        if (strcmp(line, mine) != 0) {
            fprintf(stderr, "dsm_consumer_c: point %d: dsm-lookup says %s, the C API %s\n", n + 1, line, mine);
            fclose(in);
            return 1;
        }
        if (v[0] < 1.0) ++shadowed;
        else ++lit;
        ++n;
    }
    fclose(in);
    if (n != POINT_COUNT) {
        fprintf(stderr, "dsm_consumer_c: '%s' holds %d answers, not %d\n", path, n, POINT_COUNT);
        return 1;
    }
    if (shadowed < POINT_COUNT / 10 || lit < POINT_COUNT / 10) {
        fprintf(stderr, "dsm_consumer_c: %d points shadowed and %d lit: too few of one kind to compare\n", shadowed,
                lit);
        return 1;
    }
    printf("dsm_consumer_c: %d points match dsm-lookup (%d shadowed, %d lit)\n", n, shadowed, lit);
    return 0;
}

int main(int argc, char** argv) {
    dsm_cache* cache = NULL;
    dsm_map* map = NULL;
    dsm_lookup_context* lookups = NULL;
    dsm_open_options open_options = DSM_OPEN_OPTIONS_INIT;
    dsm_lookup_options lookup_options = DSM_LOOKUP_OPTIONS_INIT;
    dsm_map_info info;
    dsm_result r;
    int status = 1;
    static double points[3 * POINT_COUNT], visibility[3 * POINT_COUNT], bounds[POINT_COUNT];

    if (argc != 3 && argc != 4) {
        fprintf(stderr, "usage: dsm_consumer_c MAP POINTS [EXPECTED]\n");
        return 2;
    }
    if ((r = dsm_cache_create(64u << 20, &cache)) != DSM_OK) return report("dsm_cache_create", r);
    open_options.cache = cache;
    if ((r = dsm_map_open(argv[1], &open_options, &map)) != DSM_OK) {
        status = report("dsm_map_open", r);
        goto done;
    }
    info.size = sizeof info;
    if ((r = dsm_map_get_info(map, &info)) != DSM_OK) {
        status = report("dsm_map_get_info", r);
        goto done;
    }
    if (argc == 3) {
        status = make_points(map, &info, points);
        if (status == 0) status = write_points(argv[2], points);
        goto done;
    }

    if (read_points(argv[2], points) != 0) goto done;
    if ((r = dsm_lookup_context_create(map, &lookups)) != DSM_OK) {
        status = report("dsm_lookup_context_create", r);
        goto done;
    }
    lookup_options.space = DSM_SPACE_LIGHT;
    if ((r = dsm_lookup(lookups, &lookup_options, POINT_COUNT, points, visibility, bounds)) != DSM_OK) {
        status = report("dsm_lookup", r);
        goto done;
    }
    status = compare(argv[3], info.channels, visibility, bounds);

done:
    dsm_lookup_context_destroy(lookups);
    dsm_map_close(map);
    dsm_cache_destroy(cache);
    return status;
}
