/* The C API of libdsm: read deep shadow maps, look them up, trace soft
 * shadows and write maps, from C99 or anything that binds to C (Rust, Python
 * ctypes, OSL renderer services, plugins). Documentation: docs/c-api.md.
 *
 * Conventions:
 * - Every object is an opaque handle made by a *_create / *_open function and
 *   released by the matching *_destroy / *_close function (NULL is accepted and
 *   ignored there).
 * - Every function that can fail returns a dsm_result. On failure the message
 *   of the failure (one line naming the file, level, tile, pixel or argument)
 *   is kept for the calling thread (dsm_last_error_message) and passed to the
 *   error callback, if one is set. Output arguments are left unchanged unless
 *   documented otherwise. No function aborts or lets a C++ exception escape.
 * - Structs of options and of information begin with `size`, which the caller
 *   sets to sizeof(the struct) (the *_INIT macros do): the library then knows
 *   which fields the caller has, so later versions can add fields at the end.
 *   Plain records (points, hits, levels) have a fixed layout.
 * - Thread-safety: maps, caches, soft lights and writers' finished files may
 *   be shared by any number of threads; a lookup context, a soft-shadow context
 *   and a writer belong to one thread at a time.
 */
#ifndef DSM_C_H
#define DSM_C_H

#include <stddef.h>
#include <stdint.h>

#if defined(_WIN32) && !defined(DSM_C_STATIC)
#if defined(DSM_C_BUILDING)
#define DSM_C_API __declspec(dllexport)
#else
#define DSM_C_API __declspec(dllimport)
#endif
#elif defined(__GNUC__)
#define DSM_C_API __attribute__((visibility("default")))
#else
#define DSM_C_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------- results */

/** What a call did. The failure codes follow dsm::ErrorCode one to one. */
typedef enum dsm_result {
    DSM_OK = 0,
    DSM_ERROR_IO = 1,          /**< a file could not be opened, read, written or renamed; a read callback failed */
    DSM_ERROR_FORMAT = 2,      /**< not a deep shadow map at all */
    DSM_ERROR_CORRUPT = 3,     /**< a map whose bytes contradict the format */
    DSM_ERROR_LIMIT = 4,       /**< an input exceeds a limit (size, memory) */
    DSM_ERROR_ARGUMENT = 5,    /**< an argument outside its documented range (also a NULL handle) */
    DSM_ERROR_SCENE = 6,       /**< an invalid scene description */
    DSM_ERROR_UNSUPPORTED = 7, /**< a valid input this version cannot handle (newer format, larger struct) */
    DSM_ERROR_INTERNAL = 8     /**< a bug in libdsm: please report it */
} dsm_result;

/** The code's name: "ok", "io", "format", "corrupt", ... ("unknown" otherwise). */
DSM_C_API const char* dsm_result_name(dsm_result result);

/** The message of the last call on this thread that failed ("" if none has).
 *  Valid until the next failing call on this thread. */
DSM_C_API const char* dsm_last_error_message(void);
/** The file the last failure on this thread concerns, as the caller named it
 *  (the path given to dsm_map_open, the name given with a buffer or callbacks,
 *  a writer's output path); "" when it names no file or none has failed.
 *  dsm_last_error_message() then starts with this file, quoted. Valid until
 *  the next failing call on this thread. */
DSM_C_API const char* dsm_last_error_file(void);
/** The code of the last call on this thread that failed (DSM_OK if none has). */
DSM_C_API dsm_result dsm_last_error(void);
/** Forgets this thread's last failure. */
DSM_C_API void dsm_clear_last_error(void);

/** Called on the failing thread with every failure, after the last error is
 *  set; `message` is valid during the call only. */
typedef void (*dsm_error_callback)(void* user, dsm_result result, const char* message);
/** Sets the process-wide error callback (NULL removes it). */
DSM_C_API void dsm_set_error_callback(dsm_error_callback callback, void* user);

/* ---------------------------------------------------------------- cache */

/** Decoded tiles, shared by the maps opened with it, evicted once
 *  `budget_bytes` are held (tiles in repeated use last; see dsm::TileCache). Maps opened without a cache share a
 *  process-wide one. A map keeps its cache alive: a cache may be destroyed
 *  while maps opened with it are still open. */
typedef struct dsm_cache dsm_cache;

DSM_C_API dsm_result dsm_cache_create(uint64_t budget_bytes, dsm_cache** cache);
DSM_C_API void dsm_cache_destroy(dsm_cache* cache);
/** Bytes of decoded tiles the cache holds now. */
DSM_C_API dsm_result dsm_cache_bytes_in_use(const dsm_cache* cache, uint64_t* bytes);

/* ---------------------------------------------------------------- opening maps */

typedef struct dsm_map dsm_map;

/** Limits for untrusted files and the cache; 0 (or NULL) keeps the default. */
typedef struct dsm_open_options {
    size_t size; /**< sizeof(dsm_open_options) */
    dsm_cache* cache;
    uint32_t max_width;
    uint32_t max_height;
    uint32_t max_vertices_per_pixel;
    uint64_t max_tile_bytes;
    uint64_t max_metadata_bytes;
} dsm_open_options;
#define DSM_OPEN_OPTIONS_INIT {sizeof(dsm_open_options), NULL, 0, 0, 0, 0, 0}

/** The caller's reads (an input hook): the map's bytes come from `read`. */
typedef struct dsm_read_callbacks {
    size_t size; /**< sizeof(dsm_read_callbacks) */
    void* user;
    /** Number of bytes in the map. */
    uint64_t total_bytes;
    /** Copies up to `count` bytes from `offset` into `buffer`; returns the
     *  number copied (fewer than `count` only at the end of the data) or -1 on
     *  failure. Called from any number of threads at once while the map is open. */
    int64_t (*read)(void* user, uint64_t offset, void* buffer, size_t count);
    /** Optional: called once when the map no longer needs `user` (after the
     *  last read, at dsm_map_close, or when the open fails). */
    void (*release)(void* user);
} dsm_read_callbacks;
#define DSM_READ_CALLBACKS_INIT {sizeof(dsm_read_callbacks), NULL, 0, NULL, NULL}

/** Opens and checks a map file (header, level table, directories, metadata);
 *  tiles are read when first looked up. `options` may be NULL. */
DSM_C_API dsm_result dsm_map_open(const char* path, const dsm_open_options* options, dsm_map** map);
/** Opens a map held in memory. The bytes are not copied: they must stay
 *  unchanged until dsm_map_close. `name` is what messages call the map (may be NULL). */
DSM_C_API dsm_result dsm_map_open_memory(const void* data, size_t size, const char* name,
                                         const dsm_open_options* options, dsm_map** map);
/** Opens a map read through callbacks. `release` is called even when this fails
 *  (unless callbacks->size is too small to trust the struct). */
DSM_C_API dsm_result dsm_map_open_callbacks(const dsm_read_callbacks* callbacks, const char* name,
                                            const dsm_open_options* options, dsm_map** map);
DSM_C_API void dsm_map_close(dsm_map* map);

/* ---------------------------------------------------------------- map information */

enum { DSM_PROJECTION_PERSPECTIVE = 0, DSM_PROJECTION_ORTHOGRAPHIC = 1 };
enum { DSM_FILTER_BOX = 0, DSM_FILTER_TRIANGLE = 1, DSM_FILTER_GAUSSIAN = 2 };

/** What a map's header says about it. Raster and light space are defined in
 *  docs/c-api.md (and dsm/map_info.h): light = world_to_light * (world, 1);
 *  screen (x/z, y/z) for a perspective light, (x, y) for an orthographic one;
 *  the screen window maps onto the raster [0, width] x [0, height], y down. */
typedef struct dsm_map_info {
    size_t size; /**< sizeof(dsm_map_info), set by the caller */
    uint32_t width;
    uint32_t height;
    uint32_t tile_size;
    int32_t channels;   /**< 1 or 3 */
    int32_t has_counts; /**< vertices carry sample counts (for soft shadows) */
    int32_t max_layers;
    uint32_t level_count;
    int32_t projection;        /**< DSM_PROJECTION_* */
    double world_to_light[16]; /**< row-major 4x4 */
    double screen_window[4];   /**< xmin, xmax, ymin, ymax */
    double near_plane;
    int32_t filter;      /**< DSM_FILTER_* the map was built with */
    double filter_width; /**< in pixels */
    double error_bound;  /**< level 0's bound on |V - exact| from compression */
    uint64_t file_bytes;
    uint32_t version_major;
    uint32_t version_minor;
} dsm_map_info;

/** One mip level (a fixed record). */
typedef struct dsm_level_info {
    uint32_t width;
    uint32_t height;
    uint32_t tiles_x;
    uint32_t tiles_y;
    double tolerance;   /**< compression tolerance of the level */
    double error_bound; /**< bound on |V - exact| of the level's functions */
    uint64_t vertex_count;
    uint64_t non_empty_pixels;
    uint64_t stored_bytes;
} dsm_level_info;

/** Fills `info` up to info->size bytes. */
DSM_C_API dsm_result dsm_map_get_info(const dsm_map* map, dsm_map_info* info);
DSM_C_API dsm_result dsm_map_get_level(const dsm_map* map, uint32_t level, dsm_level_info* info);
/** The map's JSON metadata; valid until dsm_map_close. `length` may be NULL. */
DSM_C_API dsm_result dsm_map_get_metadata(const dsm_map* map, const char** json, size_t* length);

/* ---------------------------------------------------------------- lookups */

enum { DSM_SPACE_WORLD = 0, DSM_SPACE_LIGHT = 1, DSM_SPACE_RASTER = 2 };
/** dsm_lookup_options.level: choose levels from the filter width and blend two. */
#define DSM_LEVEL_AUTO (-1)
/** dsm_lookup_options.bias, dsm_soft_shadow_options.bias: the automatic bias,
 *  which scales with the receiver's depth and the map's resolution
 *  (dsm/auto_bias.h; for soft shadows plus z_threshold). Any other value is
 *  used as given. */
#define DSM_BIAS_AUTO (-1e300)

typedef struct dsm_lookup_options {
    size_t size;          /**< sizeof(dsm_lookup_options) */
    int32_t space;        /**< DSM_SPACE_*: points are world, light-space or (raster x, raster y, light depth) */
    int32_t filter;       /**< DSM_FILTER_* */
    double filter_width;  /**< in level-0 pixels; raised to 1 (box) or 2 (others) */
    int32_t level;        /**< DSM_LEVEL_AUTO or a level (clamped to the coarsest) */
    double bias;          /**< subtracted from the depth, against self-shadowing; DSM_BIAS_AUTO: from the map */
} dsm_lookup_options;
#define DSM_LOOKUP_OPTIONS_INIT \
    {sizeof(dsm_lookup_options), DSM_SPACE_WORLD, DSM_FILTER_BOX, 1.0, DSM_LEVEL_AUTO, DSM_BIAS_AUTO}

/** Lookups for one thread: remembers the tiles and segments it used last so
 *  that coherent lookups are fast. Keeps its map open. */
typedef struct dsm_lookup_context dsm_lookup_context;

DSM_C_API dsm_result dsm_lookup_context_create(const dsm_map* map, dsm_lookup_context** context);
DSM_C_API void dsm_lookup_context_destroy(dsm_lookup_context* context);

/** Filtered visibility of `count` points (`points` holds 3 doubles each).
 *  Writes 3 doubles per point to `visibility` (a monochrome map repeats its
 *  value) and, if `error_bounds` is not NULL, one bound on |V - exact| per
 *  point. Points outside the map, behind a perspective light or carried
 *  beyond double range by the map's camera are lit (1).
 *  Every point is looked up; one that fails (not finite, a tile that cannot be
 *  read) gets the failure value V = 1 with error bound 1, and the call returns
 *  the first such failure. `options` may be NULL (DSM_LOOKUP_OPTIONS_INIT). */
DSM_C_API dsm_result dsm_lookup(dsm_lookup_context* context, const dsm_lookup_options* options, size_t count,
                                const double* points, double* visibility, double* error_bounds);

/* ---------------------------------------------------------------- shadow system */

/** One per renderer: the tile cache, the open map files and the maps, shared
 *  by every thread (as OpenImageIO's TextureSystem). Thread-safe. Lookups go
 *  through a per-thread state (dsm_shadow_thread) that serves every map of
 *  the system. */
typedef struct dsm_shadow_system dsm_shadow_system;
/** A map opened in a system: owned by it, valid until the system is destroyed. */
typedef struct dsm_map_handle dsm_map_handle;
/** Lookup state of one thread for every map of one system. Not thread-safe:
 *  one per thread. Keeps its system alive. */
typedef struct dsm_shadow_thread dsm_shadow_thread;

typedef struct dsm_shadow_system_options {
    size_t size;             /**< sizeof(dsm_shadow_system_options) */
    uint64_t cache_bytes;    /**< tile cache budget in bytes of decoded tiles */
    uint32_t max_open_files; /**< map files open at once, at least 1; closed files reopen on demand */
    uint32_t thread_tiles;   /**< tiles each thread keeps at hand (alive outside the budget) */
} dsm_shadow_system_options;
#define DSM_SHADOW_SYSTEM_OPTIONS_INIT {sizeof(dsm_shadow_system_options), 268435456u, 100u, 64u}

typedef struct dsm_shadow_system_stats {
    size_t size;                /**< sizeof(dsm_shadow_system_stats) */
    uint64_t bytes_in_use;      /**< decoded tile bytes the cache holds */
    uint64_t peak_bytes_in_use; /**< largest bytes_in_use since creation or a reset */
    uint64_t tiles_read;        /**< tiles read and decoded from files */
    uint64_t hits;              /**< cache requests answered without a read */
    uint64_t misses;            /**< cache requests that read a tile */
    uint64_t evictions;         /**< tiles dropped to stay within the budget */
    uint64_t maps;              /**< maps opened */
    uint64_t files_open;        /**< map files open now */
    uint64_t peak_files_open;   /**< most open at once since creation or a reset */
    uint64_t reopens;           /**< reopens of files closed to stay within max_open_files */
} dsm_shadow_system_stats;

/** `options` may be NULL (DSM_SHADOW_SYSTEM_OPTIONS_INIT). */
DSM_C_API dsm_result dsm_shadow_system_create(const dsm_shadow_system_options* options, dsm_shadow_system** system);
/** Destroys the system once no dsm_shadow_thread of it remains; handles die with it. */
DSM_C_API void dsm_shadow_system_destroy(dsm_shadow_system* system);
/** Opens the map at `path`, or gives the handle it already has (the path is the key). */
DSM_C_API dsm_result dsm_shadow_system_open(dsm_shadow_system* system, const char* path, dsm_map_handle** handle);
DSM_C_API dsm_result dsm_shadow_system_get_map_info(const dsm_shadow_system* system, const dsm_map_handle* handle,
                                                    dsm_map_info* info);
DSM_C_API dsm_result dsm_shadow_system_get_stats(const dsm_shadow_system* system, dsm_shadow_system_stats* stats);
DSM_C_API dsm_result dsm_shadow_system_reset_stats(dsm_shadow_system* system);
DSM_C_API dsm_result dsm_shadow_thread_create(dsm_shadow_system* system, dsm_shadow_thread** thread);
DSM_C_API void dsm_shadow_thread_destroy(dsm_shadow_thread* thread);

/** dsm_lookup for a map of a system, on `thread`: the same answers to the bit.
 *  The points are visited tile by tile, so a large batch of scattered points
 *  costs less than the same lookups one by one. Every point is looked up; one
 *  that fails gets V = 1 with error bound 1 and the call returns the first
 *  such failure. */
DSM_C_API dsm_result dsm_shadow_lookup(dsm_shadow_thread* thread, const dsm_map_handle* handle,
                                       const dsm_lookup_options* options, size_t count, const double* points,
                                       double* visibility, double* error_bounds);

/* ---------------------------------------------------------------- one pixel */

/** A visibility function as stored: vertex_count depths (non-decreasing),
 *  vertex_count * channels visibilities (vertex-major, non-increasing within
 *  a layer), optional per-vertex sample counts, and the first vertex of each
 *  layer after the first. Linear between vertices; 1 before the first vertex
 *  of a layer, its last value after its last. */
typedef struct dsm_pixel_function {
    size_t size;        /**< sizeof(dsm_pixel_function) */
    int32_t channels;   /**< 1 or 3 */
    uint32_t vertex_count;
    const float* z;
    const float* v;
    const uint32_t* counts; /**< NULL without counts */
    uint32_t layer_count;   /**< >= 1 */
    const uint32_t* layer_starts; /**< layer_count - 1 entries (NULL for one layer) */
} dsm_pixel_function;
#define DSM_PIXEL_FUNCTION_INIT {sizeof(dsm_pixel_function), 1, 0, NULL, NULL, NULL, 1, NULL}

/** One pixel's function, holding its tile in memory while it lives. */
typedef struct dsm_pixel dsm_pixel;

DSM_C_API dsm_result dsm_map_get_pixel(const dsm_map* map, uint32_t level, uint32_t x, uint32_t y, dsm_pixel** pixel);
/** Points `function` (up to function->size bytes) at the pixel's arrays, valid until dsm_pixel_release. */
DSM_C_API dsm_result dsm_pixel_get_function(const dsm_pixel* pixel, dsm_pixel_function* function);
/** The pixel's visibility at light depth z (3 doubles; a monochrome pixel repeats its value). */
DSM_C_API dsm_result dsm_pixel_evaluate(const dsm_pixel* pixel, double z, double* visibility);
DSM_C_API void dsm_pixel_release(dsm_pixel* pixel);

/* ---------------------------------------------------------------- soft shadows */

enum { DSM_AREA_LIGHT_DISK = 0, DSM_AREA_LIGHT_RECTANGLE = 1 };
enum { DSM_ATTENUATION_SUBTRACTIVE = 0, DSM_ATTENUATION_MULTIPLICATIVE = 1 };
enum { DSM_SOFT_MTSM = 0, DSM_SOFT_PCF = 1 };

/** An area light in the map's light space, centred on its axis. */
typedef struct dsm_area_light {
    size_t size;          /**< sizeof(dsm_area_light) */
    int32_t shape;        /**< DSM_AREA_LIGHT_* */
    double half_width;    /**< the radius of a disk */
    double half_height;   /**< ignored for a disk */
    /** Light-space depth of the light's plane; < 0: where the map's build put
     *  it (the area-light radius recorded in the map). */
    double plane_depth;
} dsm_area_light;
#define DSM_AREA_LIGHT_INIT {sizeof(dsm_area_light), DSM_AREA_LIGHT_DISK, 0.0, 0.0, -1.0}

typedef struct dsm_soft_shadow_options {
    size_t size;                 /**< sizeof(dsm_soft_shadow_options) */
    int32_t method;              /**< DSM_SOFT_MTSM (ray traced) or DSM_SOFT_PCF */
    int32_t samples;             /**< light samples per receiver, >= 1 */
    int32_t layers;              /**< map layers used; 0 = all */
    double z_threshold;          /**< light-space depth tolerance of a hit */
    double bias;                 /**< each ray ends this far before the receiver, >= 0, or DSM_BIAS_AUTO */
    double visibility_threshold; /**< a ray stops below this, in [0, 1] */
    uint64_t seed;
    int32_t hierarchy;      /**< walk rays through the depth quadtree (1) or every pixel (0) */
    int32_t classification; /**< classify fully lit receivers first (1) */
    int32_t attenuation;    /**< DSM_ATTENUATION_* */
} dsm_soft_shadow_options;
#define DSM_SOFT_SHADOW_OPTIONS_INIT \
    {sizeof(dsm_soft_shadow_options), DSM_SOFT_MTSM, 64, 0, 0.0, DSM_BIAS_AUTO, 1e-3, 1, 1, 1, DSM_ATTENUATION_SUBTRACTIVE}

/** A map and an area light, ready to trace; shared by threads. */
typedef struct dsm_soft_light dsm_soft_light;
/** Soft-shadow queries for one thread. */
typedef struct dsm_soft_context dsm_soft_context;

DSM_C_API dsm_result dsm_soft_light_create(const dsm_map* map, const dsm_area_light* light, dsm_soft_light** soft);
DSM_C_API void dsm_soft_light_destroy(dsm_soft_light* soft);
DSM_C_API dsm_result dsm_soft_context_create(const dsm_soft_light* soft, dsm_soft_context** context);
DSM_C_API void dsm_soft_context_destroy(dsm_soft_context* context);
/** Fraction of the light visible from `count` world points (3 doubles each):
 *  3 doubles per point to `visibility`, and the rays traced per point to
 *  `rays` if not NULL. A point that fails gets V = 1 and 0 rays; the call
 *  returns the first failure. `options` may be NULL. */
DSM_C_API dsm_result dsm_soft_shadow(dsm_soft_context* context, const dsm_soft_shadow_options* options, size_t count,
                                     const double* points, double* visibility, int32_t* rays);

/* ---------------------------------------------------------------- writing maps */

typedef struct dsm_write_options {
    size_t size; /**< sizeof(dsm_write_options) */
    uint32_t width;
    uint32_t height;
    uint32_t tile_size;   /**< a power of two from 2 to 4096 */
    int32_t channels;     /**< 1 or 3 */
    int32_t counts;       /**< store per-vertex sample counts */
    int32_t max_layers;   /**< 1..255 */
    int32_t projection;   /**< DSM_PROJECTION_* */
    double world_to_light[16];
    double screen_window[4];
    double near_plane;
    int32_t filter;
    double filter_width;
    /** Compression tolerance of raw samples, recorded for level 0. */
    double tolerance;
    uint32_t mip_levels; /**< 0 = a full pyramid, 1 = none, N = N levels */
    double level_tolerance_factor;
    int32_t zlib_level; /**< 0..9 */
    const char* metadata; /**< JSON text stored in the file; NULL = "{}" */
    /** Non-zero: compress pixels built from sample rays, and every coarser
     *  level, with centred segments (docs/dsm-build.md, "Centred
     *  compression"); 0: the greedy rule. Added in 0.1; older callers' smaller
     *  structs read as 0. */
    int32_t centred_compression;
} dsm_write_options;
#define DSM_WRITE_OPTIONS_INIT                                                                                       \
    {sizeof(dsm_write_options), 0, 0, 32, 1, 0, 1, DSM_PROJECTION_PERSPECTIVE,                                       \
     {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, {-1, 1, -1, 1}, 0.0, DSM_FILTER_BOX, 1.0, 0.0, 0, 0.5, 6, NULL, 0}

/** A surface a sample ray met: light depth and opacity per channel in [0, 1] (a fixed record). */
typedef struct dsm_surface_hit {
    float z;
    float opacity[3];
} dsm_surface_hit;

/** One sample ray of a pixel: the surfaces it met (any order) and its filter
 *  weight (>= 0) (a fixed record). */
typedef struct dsm_sample_ray {
    const dsm_surface_hit* hits;
    size_t hit_count;
    double weight;
} dsm_sample_ray;

/** Writes a map pixel by pixel to a temporary file beside `path`, renamed to
 *  `path` by dsm_writer_finish. A pixel never set is empty (lit). */
typedef struct dsm_writer dsm_writer;

DSM_C_API dsm_result dsm_writer_open(const char* path, const dsm_write_options* options, dsm_writer** writer);
/** Sets level-0 pixel (x, y) to a function as stored (checked, not recompressed). */
DSM_C_API dsm_result dsm_writer_set_pixel_function(dsm_writer* writer, uint32_t x, uint32_t y,
                                                   const dsm_pixel_function* function);
/** Sets level-0 pixel (x, y) from its sample rays: the weighted average of
 *  their transmittance, compressed with the options' tolerance (and layers,
 *  counts, channels). */
DSM_C_API dsm_result dsm_writer_set_pixel_samples(dsm_writer* writer, uint32_t x, uint32_t y,
                                                  const dsm_sample_ray* rays, size_t ray_count);
/** Writes what is left, the mip levels and the directories, and renames the
 *  file into place. The writer is then done (destroy it). */
DSM_C_API dsm_result dsm_writer_finish(dsm_writer* writer);
/** Releases the writer; without a successful finish no file named `path` is
 *  created or replaced. */
DSM_C_API void dsm_writer_destroy(dsm_writer* writer);

#ifdef __cplusplus
}
#endif

#endif /* DSM_C_H */
