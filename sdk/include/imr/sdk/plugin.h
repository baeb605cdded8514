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
 *    whoever allocated it.
 *  - Growing structs (descriptor, function tables, host services, requests, views) start with
 *    `struct_size` and are only ever extended at their end, with a minor version bump. A reader
 *    accepts any size from the struct's ABI 1.0 size (IMR_*_SIZE_1_0 below) up, reads a field only
 *    when struct_size covers it, and ignores what lies beyond its own struct.
 *  - Frozen structs have no struct_size and never change within ABI major 1: imr_camera,
 *    imr_track_observation and imr_point_estimate (they travel in arrays, whose stride is their
 *    size), imr_track_view and imr_refiner_update (filled by the plugin in the host's memory:
 *    adding a size field to them now would move every field, an ABI major bump that would break
 *    every plugin out there). A later minor that needs more adds a new struct, reached through a
 *    function appended to a function table (whose struct_size says whether the plugin has it).
 *
 * THE CONTRACT (what the host promises and what it expects; each call below says more)
 *
 *  Order. The host loads a library and calls the entry point with 0, 1, ... until NULL, before
 *  any other call into the library; it calls the entry point again only after loading the library
 *  again. It may load a library only to list or check its plugins (`imr plugins`, `imr validate`)
 *  and never create an instance. For each sequence it creates one instance per job stage, in the
 *  job's stage order, then per frame of an image input: features.process_frame(frame), then
 *  refiner.add_frame(same frame, those tracks); each keyframe then updates the engine, which calls
 *  weight_policy.transfer zero or more times; a mesh refiner's refine runs every N keyframes (the
 *  stage's every_keyframes) and once at the end, before the exports; exporters' export_mesh runs
 *  for snapshots and at the end, once per output format (each format through the first exporter
 *  stage that lists it); since ABI 1.5 a dense stage's add_frame runs per frame right after
 *  the refiner's add_frame of each frame, before a keyframe's engine update. Then
 *  it destroys every instance it created, in no promised order, and only then unloads the library.
 *
 *  Threads. Every call on an instance (create, its calls, destroy) comes from one thread, and
 *  never two at a time: an instance needs no lock for its own state. Today each sequence runs in a
 *  process of its own and every instance of that process is called from the same thread; do not
 *  rely on that for state shared between instances (globals): keep it thread-safe. A plugin may
 *  use threads of its own inside a call and must join them before the call returns. Host
 *  services may be called from any thread while the instance lives (keyframe_image: see there).
 *
 *  create and destroy. `destroy` follows every successful `create` (IMR_OK and a non-NULL
 *  instance), once, after the instance's last call. It never follows a failed `create`: a create
 *  that fails releases whatever it made and leaves *out_instance NULL.
 *
 *  Statuses. A call returns IMR_OK or, on failure, IMR_INVALID_ARGUMENT (bad params or input),
 *  IMR_ERROR (anything else), IMR_CANCELLED (the host's is_cancelled asked it to stop) or
 *  IMR_UNSUPPORTED (valid, but not something this plugin does), with a message in `error`. Every
 *  status other than IMR_OK fails the sequence (the other sequences of a batch still run) with
 *  "<plugin id>: <call> failed (<status>): <message>"; the status says what kind of failure it is,
 *  the message says which parameter, frame or file. A status outside this list is a failure too.
 *
 *  The process may end during any call. A job stage may set `timeout_seconds` (or `imr run
 *  --stage-timeout` sets one for every stage): a stage watchdog, on another thread, ends the
 *  sequence's process (exit status 124) when one call of that stage (create, process_frame,
 *  add_frame, transfer, export_mesh; not destroy) runs longer, without calling destroy or any
 *  destructor; what an exporter wrote into its staging folder is discarded. A cancelled batch
 *  sends SIGTERM (is_cancelled then returns non-zero) and SIGKILL 10 s later; a batch's memory
 *  limit kills the process too. So keep nothing that cannot be lost, and poll is_cancelled in
 *  long calls.
 *
 *  Lifetimes. Inputs (params_json, cameras, images, observations, request structs and every
 *  array or string they point to) are valid only during the call: copy what you keep. The host
 *  services table is valid for the instance's lifetime. Outputs a plugin hands back (imr_track_view,
 *  imr_refiner_update and the arrays they point to) stay owned by the plugin and must stay valid
 *  until the next call on the same instance or its destruction. A descriptor, its function table
 *  and its strings must stay valid while the library is loaded.
 *
 * Most plugin authors never touch this file directly: see plugin.hpp for the C++ wrapper (one
 * class + IMR_PLUGIN_EXPORT), and the example plugins installed with the SDK
 * (share/doc/imr_sdk/examples; sdk/examples in imr's source) for complete ones.
 */
#ifndef IMR_SDK_PLUGIN_H
#define IMR_SDK_PLUGIN_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ABI version. Major: incompatible change (the host refuses other majors). Minor: fields
 * appended at the end of growing structs; a host accepts plugins of any minor of its major (older
 * or newer than its own) and reads only the fields their struct_size covers, and a plugin does
 * the same with what the host passes. */
#define IMR_ABI_MAJOR 1
#define IMR_ABI_MINOR 6

#define IMR_ENTRY_SYMBOL "imr_plugin_entry"

#if defined(_WIN32)
#define IMR_PLUGIN_API __declspec(dllexport)
#else
#define IMR_PLUGIN_API __attribute__((visibility("default")))
#endif

/* ------------------------------------------------------------------------------------------ */
/* Status and errors                                                                          */

/* What a call returns (see "Statuses" above: every status but IMR_OK fails the sequence). */
typedef int32_t imr_status;
#define IMR_OK 0
#define IMR_ERROR 1            /* generic failure; see the message */
#define IMR_INVALID_ARGUMENT 2 /* bad parameters or input data */
#define IMR_CANCELLED 3        /* the host asked to stop (host services: is_cancelled) */
#define IMR_UNSUPPORTED 4      /* the request is valid but this plugin cannot do it */

/* Message buffer owned by the caller, empty (message[0] == 0) before the call. A plugin writes a
 * NUL-terminated UTF-8 message on failure (truncated to fit); on success it leaves it alone. */
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

/* An 8-bit image: a frame for the features plugin, a keyframe image for an exporter. Growing;
 * filled by the host. */
typedef struct imr_image_view {
  uint32_t struct_size;
  int32_t width;
  int32_t height;
  int32_t channels;       /* 1 (gray) or 3 (BGR) */
  int64_t stride_bytes;   /* bytes between rows */
  const uint8_t* pixels;  /* 8-bit, rows top to bottom */
} imr_image_view;

/* Version 1: ABI 1.0 (log, progress, is_cancelled). Version 2: ABI 1.1 (keyframe images). A
 * plugin uses a service only when struct_size covers it: a 1.1 plugin run by a 1.0 host sees a
 * 40-byte table and does without images; a 1.0 plugin never looks past its own fields. Every
 * service is safe to call from any thread until the instance's destroy returns. */
#define IMR_HOST_SERVICES_VERSION 2
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
  /* --- since ABI 1.1 (version 2) --- */
  /* The image of keyframe `index` (0 .. keyframe_count - 1 of the imr_export_request or, since
   * ABI 1.4, the imr_refine_request being served; only during export_mesh or refine, and only
   * when the request's keyframe_images is non-zero),
   * decoded by the host: 8-bit gray or BGR, the size of the keyframe's imr_camera. `*out` stays
   * valid until release_keyframe_image(index) or the end of the export_mesh (refine) call, whichever comes
   * first. The host decodes an image once and keeps it while it is held or while its cache has
   * room (a bounded budget), within one call (imr frees the decoded images between calls: an
   * exporter asked for several formats keeps what it made of them): release what you no longer
   * need. Fails with IMR_INVALID_ARGUMENT
   * (an index out of range, no export call in progress) or IMR_ERROR (the file cannot be
   * decoded, the budget is exhausted by held images), with a message in `error`. */
  imr_status (*keyframe_image)(void* host_data, uint64_t index, imr_image_view* out,
                               imr_error* error);
  /* Done with keyframe `index`'s image (a no-op when it is not held). Acquisitions are counted:
   * an image asked for twice is released after two releases. */
  void (*release_keyframe_image)(void* host_data, uint64_t index);
} imr_host_services;

/* ------------------------------------------------------------------------------------------ */
/* Plugin kinds and their function tables                                                     */

typedef enum imr_plugin_kind {
  IMR_KIND_FEATURES = 1,      /* images -> 2D tracks */
  IMR_KIND_REFINER = 2,       /* 2D tracks + cameras -> new / moved / removed 3D points */
  IMR_KIND_WEIGHT_POLICY = 3, /* removed cells' weights -> new cells' weights */
  IMR_KIND_EXPORTER = 4,      /* mesh -> files */
  IMR_KIND_MESH_REFINER = 5,  /* since ABI 1.4: mesh + keyframe images -> better vertex positions */
  IMR_KIND_DENSE = 6          /* since ABI 1.5: keyframe images + cameras -> many 3D points */
} imr_plugin_kind;

typedef struct imr_instance imr_instance; /* opaque; defined by each plugin */

/* Cameras: pinhole, world -> camera: x_cam = R * X_world + t, pixel = K * x_cam (row-major).
 * Frozen (no struct_size; an array element in imr_export_request). */
typedef struct imr_camera {
  uint64_t id;      /* frame index within the sequence */
  double K[9];      /* intrinsics, row-major */
  double R[9];      /* rotation world -> camera, row-major */
  double t[3];      /* translation world -> camera */
  int32_t width;    /* image size in pixels */
  int32_t height;
} imr_camera;

/* --- weight policy ----------------------------------------------------------------------- */
/* When the engine moves or inserts a point, the Delaunay triangulation replaces some tetrahedra
 * (the removed cells) by new ones (the added cells); a weight-transfer policy gives each added
 * cell a free-space weight from the removed cells' weights and centroids, without casting rays
 * again (the paper's policies: mean, weighted mean, nearest). */

typedef struct imr_transfer_request { /* growing; filled by the host */
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
  /* Fill request->added_weights with a finite weight for each added cell.
   * When: zero or more times per keyframe, from inside the engine's update. Called on the
   * engine's hot path: no allocation per call if avoidable, no logging.
   * Pre: added_count >= 1; removed_count may be 0 (nothing to inherit: the paper's policies give
   * 0); the arrays hold the counts the request gives, valid during the call only.
   * Returns IMR_OK, or IMR_INVALID_ARGUMENT / IMR_ERROR / IMR_CANCELLED with a message. On a
   * failure, or a weight that is not finite, the host gives the added cells weight 0, finishes the
   * update and then fails the sequence with the first message. */
  imr_status (*transfer)(imr_instance* instance, const imr_transfer_request* request,
                         imr_error* error);
} imr_weight_policy_api;

/* --- exporter ----------------------------------------------------------------------------- */

typedef struct imr_mesh_view { /* growing; filled by the host */
  uint32_t struct_size;
  uint32_t reserved0;
  const double* vertices;   /* 3 * vertex_count, packed xyz */
  uint64_t vertex_count;
  const uint32_t* faces;    /* 3 * face_count vertex indices, counter-clockwise seen from the
                               side the normal points to (toward free space) */
  uint64_t face_count;
  const int64_t* point_ids; /* vertex_count ids of the 3D points, -1 for Steiner; may be NULL */
  /* --- since ABI 1.1: read only when struct_size covers it --- */
  /* 3 * vertex_count bytes, red green blue per vertex: the colours of the 3D points as the input
   * gave them (e.g. COLMAP points3D), grey for Steiner points; NULL when the input has none. */
  const uint8_t* vertex_colors;
  /* --- since ABI 1.2: read only when struct_size covers it --- */
  /* vertex_count keys, each in 0 .. 2^48 - 1, that name the vertices across the files of one run:
   * the 3D Tiles tiles of a sequence share the vertices of their seams, and a key is the same
   * vertex (same position) in every tile that has it, so tiles merge without duplicates. A glTF
   * or GLB exporter writes them as the attribute `_VERTEX_KEY` (VEC2 FLOAT, both exact integers:
   * key = x * 2^24 + y; glTF forbids UNSIGNED_INT attributes). NULL except for tiles. */
  const int64_t* vertex_keys;
} imr_mesh_view;

typedef struct imr_export_request { /* growing; filled by the host */
  uint32_t struct_size;
  uint32_t reserved0;
  const imr_mesh_view* mesh;
  const char* directory; /* existing folder to write into (the host moves files from it) */
  const char* stem;      /* file name without extension, e.g. "mesh" */
  const char* format;    /* one of the plugin's formats, e.g. "obj", "ply", "gltf", "glb" */
  /* --- since ABI 1.1: read only when struct_size covers them --- */
  /* The sequence's keyframe cameras so far, in order (the vertices' world frame; imr_camera's
   * convention). Intrinsics K are all zero for a camera whose input gives none; width and height
   * are its image size (0 when unknown). NULL / 0 when the input has no cameras. */
  const imr_camera* keyframes;
  uint64_t keyframe_count;
  /* Non-zero when host services' keyframe_image gives the image of every keyframe (inputs with
   * images); 0 for engine-only inputs (SfM / SLAM exports, synthetic streams). */
  int32_t keyframe_images;
  uint32_t reserved1;
  /* --- since ABI 1.2: read only when struct_size covers them --- */
  /* NULL, or 3 doubles: the point the vertices of PLY and glTF/GLB are written relative to (PLY
   * `comment imr_origin`, the translation of the glTF node holding the mesh), instead of one the
   * exporter picks. The host sets it for 3D Tiles: each tile's own origin, so float32 keeps
   * millimetres. */
  const double* origin;
  /* NULL, or 9 doubles (row-major, world -> glTF): the rotation of the glTF scene's root node,
   * instead of one the exporter picks (an upright view from the keyframes). The host sets it for
   * 3D Tiles content, which is y-up glTF in a z-up tileset: (x, y, z) -> (x, z, -y). */
  const double* gltf_rotation;
  /* --- since ABI 1.6: read only when struct_size covers it --- */
  /* 0, or the world length of one texel the content needs (in the vertices' units): the host
   * sets it for a 3D Tiles level of detail, which a viewer shows only from afar (its geometric
   * error / 16: a texel about a screen pixel where the viewer turns to its children). An exporter
   * may then sample the images that coarsely instead of at their own resolution. */
  double texel_size;
} imr_export_request;

/* Since ABI 1.3: a mesh too large to hand over whole (the single mesh of a long drive, which the
 * host keeps on disk as the engine forgets: engine.forget), read in blocks during the call, as
 * often and in whatever order the exporter likes. The same mesh as an imr_mesh_view would show,
 * in the same vertex and face order. */
typedef struct imr_mesh_stream { /* growing; filled by the host */
  uint32_t struct_size;
  uint32_t reserved0;
  uint64_t vertex_count;
  uint64_t face_count;
  double bounds[6];        /* min x y z, max x y z of the vertices */
  void* context;           /* the host's; passed back to the calls below */
  /* Copies vertices [first, first + count): `xyz` 3 per vertex, `point_ids` 1 per vertex (-1
   * for Steiner points), `normal_sums` 3 per vertex: the sum over the vertex's faces, in face
   * order, of (b - a) x (c - a) for the face (a, b, c) (twice the area-weighted normal; zero
   * length for a vertex of degenerate faces only). Any of the three may be NULL. */
  imr_status (*read_vertices)(void* context, uint64_t first, uint64_t count, double* xyz,
                              int64_t* point_ids, double* normal_sums, imr_error* error);
  /* Copies faces [first, first + count): 3 vertex indices each, oriented as imr_mesh_view's. */
  imr_status (*read_faces)(void* context, uint64_t first, uint64_t count, uint32_t* faces,
                           imr_error* error);
} imr_mesh_stream;

typedef struct imr_exporter_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Comma-separated formats this exporter writes, e.g. "obj,ply,gltf,glb". */
  const char* formats;
  /* Write the mesh as directory/stem.<ext> (plus companion files the format needs).
   * When: once per output format this stage is the first to list, for each snapshot (every
   * output.snapshot_every keyframes, when set) and for the final mesh.
   * Pre: request->format is one of `formats`; the mesh has at least one face; request, mesh,
   * strings and keyframes are valid during the call only.
   * The host gives a private staging folder and moves the files to their final place only on
   * success, so a plugin need not write atomically itself; on a failure (or when the process is
   * ended mid-call) the folder is discarded.
   * Returns IMR_OK, or IMR_INVALID_ARGUMENT (a mesh or request it cannot take), IMR_UNSUPPORTED
   * (a format it does not write), IMR_ERROR (a write failed), IMR_CANCELLED, with a message;
   * each fails the sequence. Keyframe images held by the plugin are released when it returns. */
  imr_status (*export_mesh)(imr_instance* instance, const imr_export_request* request,
                            imr_error* error);
  /* --- since ABI 1.3: read only when struct_size covers it; may be NULL --- */
  /* export_mesh for a mesh the host holds on disk: `request->mesh` is NULL and the mesh is read
   * from `stream` in blocks, so the export need not hold it whole. Same contract as export_mesh,
   * and one more answer: IMR_UNSUPPORTED, with nothing written, for a request this exporter can
   * only write from the whole mesh (a format, colours or a texture it builds over the whole
   * mesh); the host then reads the mesh whole and calls export_mesh. */
  imr_status (*export_mesh_stream)(imr_instance* instance, const imr_export_request* request,
                                   const imr_mesh_stream* stream, imr_error* error);
} imr_exporter_api;

/* --- features ---------------------------------------------------------------------------- */
/* Image features tracked from frame to frame (e.g. edge points followed by Lucas-Kanade). */

typedef struct imr_track_observation { /* frozen: an array element */
  uint64_t track_id; /* stable across frames */
  double x;          /* pixel coordinates, origin at the centre of the top-left pixel */
  double y;
} imr_track_observation;

typedef struct imr_track_view { /* frozen; owned by the plugin, valid until its next call */
  const imr_track_observation* observations;
  uint64_t count;
} imr_track_view;

typedef struct imr_features_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Track features into this frame; `is_keyframe` non-zero asks to replenish. Fills `out` with
   * every track observed in this frame (count 0 and observations NULL when none).
   * When: once per frame of an image input, in frame order from frame 0; keyframes are every
   * keyframe_every-th frame and the last one.
   * Pre: camera->id is the frame index; image is 8-bit gray or BGR, the size of every frame of
   * the sequence; camera, image and pixels are valid during the call only.
   * Post: *out points into the plugin's storage, valid until its next call or destroy (the host
   * hands it to the refiner's add_frame of the same frame).
   * Returns IMR_OK, or IMR_INVALID_ARGUMENT / IMR_ERROR / IMR_CANCELLED with a message; each
   * fails the sequence. */
  imr_status (*process_frame)(imr_instance* instance, const imr_camera* camera,
                              const imr_image_view* image, int32_t is_keyframe,
                              imr_track_view* out, imr_error* error);
} imr_features_api;

/* --- refiner ----------------------------------------------------------------------------- */
/* 3D points from 2D tracks and known cameras: triangulated once seen with enough parallax,
 * refined as frames arrive (so points move), outliers removed. */

typedef struct imr_point_estimate { /* frozen: an array element */
  uint64_t id;
  double position[3];
  uint64_t first_camera; /* index into imr_refiner_update.camera_ids */
  uint64_t camera_count; /* cameras observing the point (for new points; may be 0 for moves) */
} imr_point_estimate;

typedef struct imr_refiner_update { /* frozen; owned by the plugin, valid until its next call */
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
   * refiner triangulates/refines and fills `out`; on other frames `out` is left empty.
   * When: once per frame, in frame order, right after the features' process_frame of the frame.
   * Pre: *out is zeroed; camera, observations (the features plugin's view) are valid during the
   * call only: copy what you keep.
   * Post: *out points into the plugin's storage, valid until its next call or destroy. Every
   * moved or removed id was reported new before and not removed since, new ids are new, every
   * position is finite, every camera id is a frame already given: the host checks this and fails
   * the sequence naming the point otherwise.
   * Returns IMR_OK, or IMR_INVALID_ARGUMENT (a bad camera or observation) / IMR_ERROR /
   * IMR_CANCELLED with a message; each fails the sequence. */
  imr_status (*add_frame)(imr_instance* instance, const imr_camera* camera,
                          const imr_track_observation* observations, uint64_t observation_count,
                          int32_t is_keyframe, imr_refiner_update* out, imr_error* error);
} imr_refiner_api;

/* --- mesh refiner (since ABI 1.4) --------------------------------------------------------- */
/* Moves the vertices of the surface (and may subdivide its faces) so that it agrees with the
 * keyframe images: e.g. photo-consistency between keyframes that see a face, plus a smoothness
 * term. The Delaunay points and the carving are not touched: the refined surface is the
 * pipeline's, kept between calls so that later calls start from it. */

/* Per-vertex flags of an imr_refine_request. */
#define IMR_REFINE_VERTEX_FIXED 1u   /* must not move (e.g. shared with a part already written) */
#define IMR_REFINE_VERTEX_CHANGED 2u /* new, or moved by the reconstruction, since the last call
                                        (every vertex on the first call): its position is the
                                        reconstruction's, not a refined one */

typedef struct imr_refine_request { /* growing; filled by the host */
  uint32_t struct_size;
  uint32_t reserved0;
  /* The surface: vertices where the last call left them (refined) unless flagged CHANGED; faces
   * oriented as for an export (counter-clockwise seen from free space, where the cameras are);
   * point ids (-1: Steiner); colours when the input has them. vertex_keys is NULL. */
  const imr_mesh_view* mesh;
  const uint8_t* vertex_flags; /* vertex_count IMR_REFINE_VERTEX_* bits */
  /* Every keyframe so far, in order (imr_camera's convention; K all zero when the input gives
   * no intrinsics). Their images through host services' keyframe_image when keyframe_images is
   * non-zero. Keyframes [recent_keyframes_begin, keyframe_count) arrived since the last call. */
  const imr_camera* keyframes;
  uint64_t keyframe_count;
  uint64_t recent_keyframes_begin;
  int32_t keyframe_images;
  int32_t final_call; /* non-zero: the last call of the sequence, before the exports */
} imr_refine_request;

/* Filled by the plugin; it and its arrays stay owned by the plugin, valid until its next call
 * on the same instance or its destruction. */
typedef struct imr_refine_result { /* growing; filled by the plugin */
  uint32_t struct_size; /* the plugin's sizeof(imr_refine_result) */
  uint32_t reserved0;
  /* 3 * vertex_count: the request's vertices at their new positions, in their order, then the
   * vertices the plugin added (subdivision; they are no 3D point: point id -1, grey). */
  const double* vertices;
  uint64_t vertex_count; /* >= the request's vertex_count */
  /* 3 * face_count indices into `vertices`, oriented as the request's; NULL: the request's faces
   * unchanged (then vertex_count equals the request's). */
  const uint32_t* faces;
  uint64_t face_count;
} imr_refine_result;

typedef struct imr_mesh_refiner_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Refine the surface of `request` into `out`.
   * When: every `every_keyframes` keyframes of the stage (0: never during the run), and once at
   * the end (final_call non-zero) before the mesh is exported or evaluated.
   * Pre: *out is zeroed; the request and everything it points to are valid during the call only.
   * Post: the result is a 2-manifold with the request's boundary loops, every position finite,
   * no FIXED vertex moved: the host checks and fails the sequence naming what broke. Vertices
   * the plugin added do not survive to the next call (the host passes the request's vertices
   * only, at their refined positions, with the faces the reconstruction has then).
   * Returns IMR_OK, or IMR_INVALID_ARGUMENT (a request it cannot take: e.g. no intrinsics),
   * IMR_ERROR (an image that cannot be read), IMR_CANCELLED, with a message; each fails the
   * sequence. Keyframe images held by the plugin are released when it returns. */
  imr_status (*refine)(imr_instance* instance, const imr_refine_request* request,
                       imr_refine_result* out, imr_error* error);
} imr_mesh_refiner_api;

/* --- dense (since ABI 1.5) ------------------------------------------------------------------ */
/* Dense evidence from the keyframe images: per keyframe, depth for many pixels against its
 * neighbouring keyframes (plane sweep, PatchMatch), kept where several views agree, handed to the
 * host as 3D points with the keyframes that see them. The engine carves with them as with the
 * refiner's points: each observing camera's ray to the point is free space. The plugin keeps the
 * keyframes it needs (a window of its own), so its memory stays bounded on a long drive. */

typedef struct imr_dense_request { /* growing; filled by the host */
  uint32_t struct_size;
  uint32_t reserved0;
  const imr_camera* camera;    /* the frame's camera; its id is the frame index */
  const imr_image_view* image; /* its image: 8-bit gray or BGR, the size of camera->width/height */
  int32_t is_keyframe;         /* non-zero: a keyframe (points are reported on keyframes only) */
  int32_t final_call;          /* non-zero: the sequence's last frame (report what is pending) */
} imr_dense_request;

typedef struct imr_dense_api {
  uint32_t struct_size;
  uint32_t reserved0;
  /* Take one frame; on a keyframe, fill `out` with the points found since the last keyframe
   * (new points with their observing frames; removed ids of the plugin's earlier points;
   * moved_count 0); on other frames leave it empty. Keep the frames you need (a depth map of a
   * keyframe is matched against frames on both sides of it, so its points come a few frames
   * later, with the next keyframe).
   * When: once per frame of an image input, in frame order, right after the refiner's add_frame
   * of the same frame.
   * Pre: *out is zeroed; the request and everything it points to are valid during the call only.
   * Post: *out points into the plugin's storage, valid until its next call or destroy. Ids are the
   * plugin's own (below 2^23: the host keeps them apart from the refiner's, which stay below it too,
   * and both fit an exporter's 24-bit point-id channel), new ids are new,
   * removed ids were reported new before, positions finite, every camera id a frame already
   * given: the host checks and fails the sequence naming the point otherwise.
   * Returns IMR_OK, or IMR_INVALID_ARGUMENT (a camera without intrinsics, an image of another
   * size) / IMR_ERROR / IMR_CANCELLED with a message; each fails the sequence. */
  imr_status (*add_frame)(imr_instance* instance, const imr_dense_request* request,
                          imr_refiner_update* out, imr_error* error);
} imr_dense_api;

/* ------------------------------------------------------------------------------------------ */
/* The descriptor                                                                              */

typedef struct imr_plugin_descriptor { /* growing; filled by the plugin */
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

  /* Make an instance from params (a JSON object, "{}" when none) and the host's services.
   * When: once per job stage naming this plugin, per sequence, before any call on the instance.
   * Pre: params_json is the stage's `params`, checked by the host against params_schema with its
   * defaults filled in; valid during the call only. `host` stays valid for the instance's
   * lifetime (keep the pointer).
   * Post: IMR_OK with *out_instance non-NULL; or IMR_INVALID_ARGUMENT (bad params) / IMR_ERROR /
   * IMR_CANCELLED with a message and *out_instance NULL: nothing to destroy, the sequence fails
   * naming the stage. */
  imr_status (*create)(const char* params_json, const imr_host_services* host,
                       imr_instance** out_instance, imr_error* error);
  /* Release an instance: once per successful create, after its last call, on the thread that
   * made the calls; never after a failed create. Cannot fail. Not watched by the stage watchdog,
   * and not called when the process is ended (see "The process may end during any call"). */
  void (*destroy)(imr_instance* instance);

  /* Exactly one is non-NULL, matching `kind` (mesh_refiner and dense, below, for those kinds);
   * its struct_size covers at least its ABI 1.0 size (1.4 for the mesh refiner's, 1.5 for the
   * dense one's). */
  const imr_features_api* features;
  const imr_refiner_api* refiner;
  const imr_weight_policy_api* weight_policy;
  const imr_exporter_api* exporter;
  /* --- since ABI 1.4: read only when struct_size covers it (a 1.0-1.3 plugin's reserved[0],
   * zero) --- */
  const imr_mesh_refiner_api* mesh_refiner;
  /* --- since ABI 1.5: read only when struct_size covers it (a 1.0-1.4 plugin's reserved[0],
   * zero) --- */
  const imr_dense_api* dense;

  void* reserved[6]; /* for future minor versions; zero */
} imr_plugin_descriptor;

/* The entry point every plugin library exports. Returns the index-th descriptor of the library,
 * or NULL past the last one. The returned descriptor lives as long as the library is loaded.
 * Called with 0, 1, ... right after the library is loaded, on the loading thread: cheap, no side
 * effects, no host services (none are given). A descriptor the host refuses (another ABI major,
 * a struct smaller than its 1.0 size, a missing id/create/destroy/table, a malformed
 * params_schema) is reported with the library's path and skipped; the library's other plugins
 * still load. */
typedef const imr_plugin_descriptor* (*imr_plugin_entry_fn)(uint32_t index);

#ifdef __cplusplus
} /* extern "C" */
#endif

/* The smallest size a reader accepts for each growing struct: its size in ABI 1.0 (every field
 * it has had since). A host refuses a descriptor or function table smaller than this; a plugin may
 * refuse (IMR_INVALID_ARGUMENT) a request smaller than this. Between this and its own sizeof, a
 * reader uses a field only when struct_size covers it. */
#define IMR_DESCRIPTOR_SIZE_1_0 96 /* up to `exporter`; the reserved tail is not needed */
#define IMR_HOST_SERVICES_SIZE_1_0 40
#define IMR_IMAGE_VIEW_SIZE_1_0 32
#define IMR_TRANSFER_REQUEST_SIZE_1_0 56
#define IMR_MESH_VIEW_SIZE_1_0 48
#define IMR_EXPORT_REQUEST_SIZE_1_0 40
#define IMR_MESH_VIEW_SIZE_1_1 56     /* up to vertex_colors */
#define IMR_EXPORT_REQUEST_SIZE_1_1 64 /* up to reserved1 */
#define IMR_WEIGHT_POLICY_API_SIZE_1_0 16
#define IMR_EXPORTER_API_SIZE_1_0 24
#define IMR_FEATURES_API_SIZE_1_0 16
#define IMR_REFINER_API_SIZE_1_0 16
#define IMR_DESCRIPTOR_SIZE_1_4 104 /* up to mesh_refiner: what a mesh refiner's needs */
#define IMR_REFINE_REQUEST_SIZE_1_4 56
#define IMR_REFINE_RESULT_SIZE_1_4 40
#define IMR_MESH_REFINER_API_SIZE_1_4 16
#define IMR_DESCRIPTOR_SIZE_1_5 112 /* up to dense: what a dense plugin's needs */
#define IMR_DENSE_REQUEST_SIZE_1_5 32
#define IMR_DENSE_API_SIZE_1_5 16
#define IMR_EXPORT_REQUEST_SIZE_1_2 80 /* up to gltf_rotation */

/* Pin the layout: these offsets are the ABI. Changing one is an ABI major bump. Checked by C11
 * and C++ compilers alike. */
#ifdef __cplusplus
#define IMR_STATIC_ASSERT(condition, message) static_assert(condition, message)
#else
#define IMR_STATIC_ASSERT(condition, message) _Static_assert(condition, message)
#endif
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, struct_size) == 0, "ABI: descriptor prefix");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, abi_major) == 4, "ABI: descriptor prefix");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, abi_minor) == 6, "ABI: descriptor prefix");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, kind) == 8, "ABI: descriptor layout");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, id) == 16, "ABI: descriptor layout");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, params_schema) == 40, "ABI: descriptor layout");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, create) == 48, "ABI: descriptor layout");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, exporter) == 88, "ABI: descriptor layout");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, mesh_refiner) == IMR_DESCRIPTOR_SIZE_1_0,
                  "ABI: descriptor 1.0 size");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, dense) == IMR_DESCRIPTOR_SIZE_1_4,
                  "ABI: descriptor 1.4");
IMR_STATIC_ASSERT(offsetof(imr_plugin_descriptor, reserved) == IMR_DESCRIPTOR_SIZE_1_5,
                  "ABI: descriptor 1.5");
IMR_STATIC_ASSERT(sizeof(imr_dense_request) == IMR_DENSE_REQUEST_SIZE_1_5, "ABI: dense request");
IMR_STATIC_ASSERT(offsetof(imr_export_request, texel_size) == IMR_EXPORT_REQUEST_SIZE_1_2,
                  "ABI: export request 1.6");
IMR_STATIC_ASSERT(sizeof(imr_dense_api) == IMR_DENSE_API_SIZE_1_5, "ABI: dense table");
IMR_STATIC_ASSERT(sizeof(imr_refine_request) == IMR_REFINE_REQUEST_SIZE_1_4, "ABI: refine request");
IMR_STATIC_ASSERT(sizeof(imr_refine_result) == IMR_REFINE_RESULT_SIZE_1_4, "ABI: refine result");
IMR_STATIC_ASSERT(sizeof(imr_mesh_refiner_api) == IMR_MESH_REFINER_API_SIZE_1_4,
                  "ABI: mesh refiner table");
IMR_STATIC_ASSERT(sizeof(imr_plugin_descriptor) == 160, "ABI: descriptor size");
IMR_STATIC_ASSERT(sizeof(imr_host_services) == 56, "ABI: host services size");
IMR_STATIC_ASSERT(offsetof(imr_host_services, keyframe_image) == IMR_HOST_SERVICES_SIZE_1_0,
                  "ABI: host services 1.1");
IMR_STATIC_ASSERT(sizeof(imr_error) == IMR_ERROR_MESSAGE_CAPACITY, "ABI: error buffer");
IMR_STATIC_ASSERT(sizeof(imr_transfer_request) == IMR_TRANSFER_REQUEST_SIZE_1_0,
                  "ABI: transfer request");
IMR_STATIC_ASSERT(sizeof(imr_mesh_view) == 64, "ABI: mesh view");
IMR_STATIC_ASSERT(offsetof(imr_mesh_view, vertex_colors) == IMR_MESH_VIEW_SIZE_1_0,
                  "ABI: mesh view 1.1");
IMR_STATIC_ASSERT(offsetof(imr_mesh_view, vertex_keys) == IMR_MESH_VIEW_SIZE_1_1,
                  "ABI: mesh view 1.2");
IMR_STATIC_ASSERT(sizeof(imr_export_request) == 88, "ABI: export request");
IMR_STATIC_ASSERT(offsetof(imr_export_request, keyframes) == IMR_EXPORT_REQUEST_SIZE_1_0,
                  "ABI: export request 1.1");
IMR_STATIC_ASSERT(offsetof(imr_export_request, origin) == IMR_EXPORT_REQUEST_SIZE_1_1,
                  "ABI: export request 1.2");
IMR_STATIC_ASSERT(sizeof(imr_image_view) == IMR_IMAGE_VIEW_SIZE_1_0, "ABI: image view");
IMR_STATIC_ASSERT(sizeof(imr_weight_policy_api) == IMR_WEIGHT_POLICY_API_SIZE_1_0,
                  "ABI: weight policy table");
IMR_STATIC_ASSERT(offsetof(imr_exporter_api, export_mesh_stream) == IMR_EXPORTER_API_SIZE_1_0,
                  "ABI: exporter table 1.3");
IMR_STATIC_ASSERT(sizeof(imr_exporter_api) == 32, "ABI: exporter table");
IMR_STATIC_ASSERT(sizeof(imr_mesh_stream) == 96, "ABI: mesh stream");
IMR_STATIC_ASSERT(sizeof(imr_features_api) == IMR_FEATURES_API_SIZE_1_0, "ABI: features table");
IMR_STATIC_ASSERT(sizeof(imr_refiner_api) == IMR_REFINER_API_SIZE_1_0, "ABI: refiner table");
IMR_STATIC_ASSERT(sizeof(imr_camera) == 184, "ABI: camera (frozen)");
IMR_STATIC_ASSERT(sizeof(imr_track_observation) == 24, "ABI: track observation (frozen)");
IMR_STATIC_ASSERT(sizeof(imr_track_view) == 16, "ABI: track view (frozen)");
IMR_STATIC_ASSERT(sizeof(imr_point_estimate) == 48, "ABI: point estimate (frozen)");
IMR_STATIC_ASSERT(sizeof(imr_refiner_update) == 64, "ABI: refiner update (frozen)");

#endif /* IMR_SDK_PLUGIN_H */
