/* imr plugin SDK: the stable C boundary between the imr host and its plugins.
 *
 * A plugin is a shared object that exports one C symbol, `imr_plugin_entry` (IMR_ENTRY_SYMBOL).
 * The host calls it with index 0, 1, 2, ... until it returns NULL; each call returns a
 * descriptor of one plugin in the library. A descriptor starts with its own size and the ABI
 * version it was built against; the host refuses a descriptor whose ABI major differs from its own.
 *
 * Rules of the boundary (so that a plugin built by another team, another day, keeps working):
 *  - Only C types cross it: fixed-width integers, doubles, pointer + count views, UTF-8 strings.
 *    Plugin parameters arrive as one JSON string.
 *  - Nothing throws across it: every function returns an imr_status and, on failure, writes a
 *    message into the caller's imr_error buffer.
 *  - Instances are opaque handles made by `create` and released by `destroy`. Memory is freed by
 *    whoever allocated it: outputs a plugin hands back (views) stay owned by the plugin and valid
 *    until the next call on the same instance or its destruction.
 *  - Structs are only ever extended at their end, with a minor version bump; every struct the host
 *    passes in starts with `struct_size` so a plugin can tell which fields exist.
 *
 * Most plugin authors never touch this file directly: see plugin.hpp for the C++ wrapper (one
 * class + IMR_PLUGIN_EXPORT), and examples/ for a complete plugin.
 */
#ifndef IMR_SDK_PLUGIN_H
#define IMR_SDK_PLUGIN_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ABI version. Major: incompatible change (the host refuses other majors). Minor: fields
 * appended at the end of structs; a host accepts plugins of any minor of its major and reads only
 * the fields their struct_size covers. */
#define IMR_ABI_MAJOR 1
#define IMR_ABI_MINOR 0

#define IMR_ENTRY_SYMBOL "imr_plugin_entry"

#if defined(_WIN32)
#define IMR_PLUGIN_API __declspec(dllexport)
#else
#define IMR_PLUGIN_API __attribute__((visibility("default")))
#endif

/* ------------------------------------------------------------------------------------------ */
/* Status and errors                                                                          */

typedef int32_t imr_status;
#define IMR_OK 0
#define IMR_ERROR 1            /* generic failure; see the message */
#define IMR_INVALID_ARGUMENT 2 /* bad parameters or input data */
#define IMR_CANCELLED 3        /* the host asked to stop (host services: is_cancelled) */
#define IMR_UNSUPPORTED 4      /* the request is valid but this plugin cannot do it */

/* Message buffer owned by the caller. A plugin writes a NUL-terminated UTF-8 message on failure
 * (truncated to fit). */
#define IMR_ERROR_MESSAGE_CAPACITY 1024
typedef struct imr_error {
  char message[IMR_ERROR_MESSAGE_CAPACITY];
} imr_error;

/* ------------------------------------------------------------------------------------------ */
/* Host services: handed to every instance at creation. Versioned function table.             */

#define IMR_LOG_DEBUG 0
#define IMR_LOG_INFO 1
#define IMR_LOG_WARNING 2
#define IMR_LOG_ERROR 3

#define IMR_HOST_SERVICES_VERSION 1
typedef struct imr_host_services {
  uint32_t struct_size; /* sizeof(imr_host_services) as the host knows it */
  uint32_t version;     /* IMR_HOST_SERVICES_VERSION */
  void* host_data;      /* pass back as first argument of every service */
  /* Log one line (UTF-8, no trailing newline needed). */
  void (*log)(void* host_data, int32_t level, const char* message);
  /* Progress of the current long call, fraction in [0, 1]; message may be NULL. */
  void (*progress)(void* host_data, double fraction, const char* message);
  /* Non-zero when the host wants the current call to stop early (return IMR_CANCELLED). */
  int32_t (*is_cancelled)(void* host_data);
} imr_host_services;

/* ------------------------------------------------------------------------------------------ */
/* Plugin kinds and their function tables                                                     */

typedef enum imr_plugin_kind {
  IMR_KIND_FEATURES = 1,      /* images -> 2D tracks */
  IMR_KIND_REFINER = 2,       /* 2D tracks + cameras -> new / moved / removed 3D points */
  IMR_KIND_WEIGHT_POLICY = 3, /* removed cells' weights -> new cells' weights */
  IMR_KIND_EXPORTER = 4       /* mesh -> files */
} imr_plugin_kind;

typedef struct imr_instance imr_instance; /* opaque; defined by each plugin */

/* Cameras: pinhole, world -> camera: x_cam = R * X_world + t, pixel = K * x_cam (row-major). */
typedef struct imr_camera {
  uint64_t id;      /* frame index within the sequence */
  double K[9];      /* intrinsics, row-major */
  double R[9];      /* rotation world -> camera, row-major */
  double t[3];      /* translation world -> camera */
  int32_t width;    /* image size in pixels */
  int32_t height;
} imr_camera;

/* --- weight policy (DESIGN.md section 3, "Weight-transfer policies") ---------------------- */

typedef struct imr_transfer_request {
  uint32_t struct_size;
  uint32_t reserved0;
  const double* removed_centroids; /* 3 * removed_count doubles, packed xyz */
  const double* removed_weights;   /* removed_count */
  uint64_t removed_count;
  const double* added_centroids;   /* 3 * added_count doubles, packed xyz */
  uint64_t added_count;
  double* added_weights;           /* out: added_count doubles, allocated by the host */
} imr_transfer_request;

typedef struct imr_weight_policy_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Fill request->added_weights. Called on the engine's hot path: no allocation per call if
   * avoidable, no logging. */
  imr_status (*transfer)(imr_instance* instance, const imr_transfer_request* request,
                         imr_error* error);
} imr_weight_policy_api;

/* --- exporter ----------------------------------------------------------------------------- */

typedef struct imr_mesh_view {
  uint32_t struct_size;
  uint32_t reserved0;
  const double* vertices;   /* 3 * vertex_count, packed xyz */
  uint64_t vertex_count;
  const uint32_t* faces;    /* 3 * face_count vertex indices, counter-clockwise seen from the
                               side the normal points to (toward free space) */
  uint64_t face_count;
  const int64_t* point_ids; /* vertex_count ids of the 3D points, -1 for Steiner; may be NULL */
} imr_mesh_view;

typedef struct imr_export_request {
  uint32_t struct_size;
  uint32_t reserved0;
  const imr_mesh_view* mesh;
  const char* directory; /* existing folder to write into (the host moves files from it) */
  const char* stem;      /* file name without extension, e.g. "mesh" */
  const char* format;    /* one of the plugin's formats, e.g. "obj", "ply", "gltf", "glb" */
} imr_export_request;

typedef struct imr_exporter_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Comma-separated formats this exporter writes, e.g. "obj,ply,gltf,glb". */
  const char* formats;
  /* Write the mesh as directory/stem.<ext> (plus companion files the format needs). The host
   * gives a private staging folder and moves the files to their final place only on success, so
   * a plugin need not write atomically itself. */
  imr_status (*export_mesh)(imr_instance* instance, const imr_export_request* request,
                            imr_error* error);
} imr_exporter_api;

/* --- features (DESIGN.md section 5) ------------------------------------------------------- */

typedef struct imr_image_view {
  uint32_t struct_size;
  int32_t width;
  int32_t height;
  int32_t channels;       /* 1 (gray) or 3 (BGR) */
  int64_t stride_bytes;   /* bytes between rows */
  const uint8_t* pixels;  /* 8-bit */
} imr_image_view;

typedef struct imr_track_observation {
  uint64_t track_id; /* stable across frames */
  double x;          /* pixel coordinates, origin at the centre of the top-left pixel */
  double y;
} imr_track_observation;

typedef struct imr_track_view { /* owned by the plugin, valid until its next call */
  const imr_track_observation* observations;
  uint64_t count;
} imr_track_view;

typedef struct imr_features_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Track features into this frame; `is_keyframe` non-zero asks to replenish. Returns every track
   * observed in this frame. */
  imr_status (*process_frame)(imr_instance* instance, const imr_camera* camera,
                              const imr_image_view* image, int32_t is_keyframe,
                              imr_track_view* out, imr_error* error);
} imr_features_api;

/* --- refiner (DESIGN.md section 5) -------------------------------------------------------- */

typedef struct imr_point_estimate {
  uint64_t id;
  double position[3];
  uint64_t first_camera; /* index into imr_refiner_update.camera_ids */
  uint64_t camera_count; /* cameras observing the point (for new points; may be 0 for moves) */
} imr_point_estimate;

typedef struct imr_refiner_update { /* owned by the plugin, valid until its next call */
  const imr_point_estimate* new_points;
  uint64_t new_count;
  const imr_point_estimate* moved_points;
  uint64_t moved_count;
  const uint64_t* removed_ids;
  uint64_t removed_count;
  const uint64_t* camera_ids; /* observing camera ids referenced by the point estimates */
  uint64_t camera_id_count;
} imr_refiner_update;

typedef struct imr_refiner_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Feed one frame's camera and track observations. On keyframes (`is_keyframe` non-zero) the
   * refiner triangulates/refines and fills `out`; on other frames `out` is left empty. */
  imr_status (*add_frame)(imr_instance* instance, const imr_camera* camera,
                          const imr_track_observation* observations, uint64_t observation_count,
                          int32_t is_keyframe, imr_refiner_update* out, imr_error* error);
} imr_refiner_api;

/* ------------------------------------------------------------------------------------------ */
/* The descriptor                                                                              */

typedef struct imr_plugin_descriptor {
  /* --- fixed prefix: never changes, in any ABI version --- */
  uint32_t struct_size; /* sizeof(imr_plugin_descriptor) as the plugin was built */
  uint16_t abi_major;   /* IMR_ABI_MAJOR the plugin was built against */
  uint16_t abi_minor;   /* IMR_ABI_MINOR the plugin was built against */
  /* --- ABI major 1 --- */
  int32_t kind;              /* imr_plugin_kind */
  uint32_t reserved0;
  const char* id;            /* reverse-DNS, unique: "org.imr.policy.nearest" */
  const char* version;       /* the plugin's own version, "1.2.0" */
  const char* description;   /* one line for `imr plugins` */
  /* JSON object describing accepted params, so `imr validate` can check a job without creating
   * instances: {"name": {"type": "integer"|"number"|"boolean"|"string"|"string_array",
   * "default": ..., "minimum": ..., "maximum": ..., "enum": [...], "description": "..."}}.
   * Unknown params are errors. */
  const char* params_schema;

  /* Make an instance from params (a JSON object, "{}" when none) and the host's services (kept
   * by the instance; valid for its lifetime). */
  imr_status (*create)(const char* params_json, const imr_host_services* host,
                       imr_instance** out_instance, imr_error* error);
  void (*destroy)(imr_instance* instance);

  /* Exactly one is non-NULL, matching `kind`. */
  const imr_features_api* features;
  const imr_refiner_api* refiner;
  const imr_weight_policy_api* weight_policy;
  const imr_exporter_api* exporter;

  void* reserved[8]; /* for future minor versions; zero */
} imr_plugin_descriptor;

/* The entry point every plugin library exports. Returns the index-th descriptor of the library,
 * or NULL past the last one. The returned descriptor lives as long as the library is loaded. */
typedef const imr_plugin_descriptor* (*imr_plugin_entry_fn)(uint32_t index);

#ifdef __cplusplus
} /* extern "C" */
#endif

#ifdef __cplusplus
/* Pin the layout: these offsets are the ABI. Changing one is an ABI major bump. */
static_assert(offsetof(imr_plugin_descriptor, struct_size) == 0, "ABI: descriptor prefix");
static_assert(offsetof(imr_plugin_descriptor, abi_major) == 4, "ABI: descriptor prefix");
static_assert(offsetof(imr_plugin_descriptor, abi_minor) == 6, "ABI: descriptor prefix");
static_assert(offsetof(imr_plugin_descriptor, kind) == 8, "ABI: descriptor layout");
static_assert(offsetof(imr_plugin_descriptor, id) == 16, "ABI: descriptor layout");
static_assert(offsetof(imr_plugin_descriptor, params_schema) == 40, "ABI: descriptor layout");
static_assert(offsetof(imr_plugin_descriptor, create) == 48, "ABI: descriptor layout");
static_assert(offsetof(imr_plugin_descriptor, exporter) == 88, "ABI: descriptor layout");
static_assert(sizeof(imr_plugin_descriptor) == 160, "ABI: descriptor size");
static_assert(sizeof(imr_host_services) == 40, "ABI: host services size");
static_assert(sizeof(imr_error) == IMR_ERROR_MESSAGE_CAPACITY, "ABI: error buffer");
static_assert(sizeof(imr_transfer_request) == 56, "ABI: transfer request");
static_assert(sizeof(imr_mesh_view) == 48, "ABI: mesh view");
static_assert(sizeof(imr_export_request) == 40, "ABI: export request");
static_assert(sizeof(imr_camera) == 184, "ABI: camera");
static_assert(sizeof(imr_track_observation) == 24, "ABI: track observation");
static_assert(sizeof(imr_point_estimate) == 48, "ABI: point estimate");
#endif

#endif /* IMR_SDK_PLUGIN_H */
