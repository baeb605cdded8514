// The batch viewer page (issue 6): one self-contained HTML page per batch folder with the summary
// table, the plots, and each sequence's mesh viewable in 3D in the browser — with Google's
// <model-viewer> (npm @google/model-viewer, its UMD build, which bundles three.js) copied into
// RUN_DIR/assets/, so nothing is fetched from the network when the page is viewed.
//
// It works opened straight from disk (file://), where browsers refuse fetch() of local files:
// each mesh is written as a small script, assets/meshes/<n>.js, holding the GLB in base64; the
// page loads it with a <script> tag when the mesh is asked for (the first one at once) and hands
// the bytes to <model-viewer> as a blob: URL. A .gltf with its .bin (no .glb beside it) is packed
// into a GLB on the way (with its texture images). A textured or vertex-coloured mesh shows its
// own colours; a plain one is painted orange so that its shape shows. The meshes stay where they
// are; the page also links them. imr's glTF meshes stand upright (their root node's rotation,
// +Y up), so the view opens looking the way the cameras looked.
//
// A run with 3D Tiles (output.tiles: tileset.json in its output folder) is shown as tiles too,
// with NASA-AMMOS' 3d-tiles-renderer on three.js (tiles_viewer.js, bundled at build time into
// imr-tiles-viewer.js, copied into RUN_DIR/assets/): its tileset.json and tiles are written as
// scripts, assets/tiles/<n>/{tileset,tile_NNNNNN}.js, which the view loads when the renderer
// asks for a tile (tiles out of view are never loaded); nothing is fetched from the network.
//
// Written files (each atomically; index.html last): RUN_DIR/index.html,
// RUN_DIR/assets/model-viewer-umd.min.js, RUN_DIR/assets/meshes/<n>.js, and for tiled runs
// RUN_DIR/assets/imr-tiles-viewer.js and RUN_DIR/assets/tiles/<n>/*.js.
//
// The `summary` it reads (what `imr run` / `imr report` hand over):
//
//   {
//     "title": "...",            optional: the page's heading (else options.title)
//     "job": "/path/job.json",   optional: shown under the heading
//     "sequences": [             one row each, in this order
//       {
//         "name": "street",                       string
//         "ok": true,                             bool (or "status": "ok" | "failed" | "not run"
//                                                 | ..., as host/batch's summary.json writes it)
//         "error": "",                            string: why it failed ("" or null when ok)
//         "output_directory": "/runs/street",     string (or "output"); relative: to RUN_DIR
//         "files": ["/runs/street/mesh.glb", ...],  written outputs (absolute, or relative to
//                                                 RUN_DIR); when absent, output_directory is
//                                                 searched for *.glb / *.gltf
//         "seconds": 12.5,                        number (or null)
//         "report": { ... }                       the sequence's report.json contents; when
//                                                 absent, output_directory/report.json is read
//       }, ...
//     ]
//   }
//
// These are pipeline::SequenceResult's fields (host/pipeline/run.h); host/batch's summary.json
// rows ({name, status, output, seconds, frames, keyframes, mesh, accuracy, error}) work as well.
// From each report the table shows: frames (report.input.summary.frames, else the row's
// "frames", else the engine's keyframes), mesh vertices/faces (report.mesh), accuracy (the mean
// distance from ground truth to the mesh: report.accuracy.truth_to_mesh.mean from `imr
// evaluate`, else report.accuracy.mean_truth_to_mesh from the synthetic sources).
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace imr::report {

struct ViewerPageOptions {
  std::string title = "imr batch";  // the page's heading when the summary has no "title"
  // The <model-viewer> script to copy (model-viewer-umd.min.js). Empty: FindModelViewerScript().
  // When none is found the page is still written, without the 3D view, and says why.
  std::filesystem::path model_viewer_script;
  // PNGs to show, absolute or relative to RUN_DIR. Empty: every *.png in RUN_DIR and
  // RUN_DIR/plots (sorted by name).
  std::vector<std::filesystem::path> plots;
  // Meshes (GLB bytes) larger than this are linked but not embedded for the 3D view.
  std::uintmax_t max_mesh_bytes = std::uintmax_t{128} << 20;
  // The tiles view's script (imr-tiles-viewer.js: 3d-tiles-renderer bundled at build time).
  // Empty: FindTilesViewerScript(); when none is found, tiled runs are listed without it.
  std::filesystem::path tiles_viewer_script;
  // A run's tiles (all of them, bytes) above this are linked but not embedded for the view.
  std::uintmax_t max_tiles_bytes = std::uintmax_t{256} << 20;
  // The page's template (viewer_page.html). Empty: FindViewerPageTemplate(); without one no
  // page is written.
  std::filesystem::path page_template;

  // Empty when usable, else which field and why.
  std::string Check() const;
};

struct ViewerPageResult {
  std::filesystem::path page;                // RUN_DIR/index.html
  std::vector<std::filesystem::path> files;  // everything written, the page last
  int meshes_viewable = 0;                   // sequences with a 3D view
  int tilesets_viewable = 0;                 // sequences with a view of their 3D Tiles
  std::vector<std::string> notes;            // what is missing and why (no model-viewer, a mesh
                                             // too large, a report that could not be read, ...)
  std::vector<std::string> info;             // what the page leaves out by the job's choice, said
                                             // once (sequences that wrote no .glb/.gltf: no 3D
                                             // view): not a problem, no warning
};

// Writes the page into `run_dir` (which must exist). Throws std::invalid_argument for a summary
// of the wrong shape (naming the key) or bad options, std::runtime_error naming the file when
// something cannot be read or written.
ViewerPageResult WriteBatchPage(const std::filesystem::path& run_dir,
                                const nlohmann::json& summary,
                                const ViewerPageOptions& options = {});

// Where the tiles view's script is: $IMR_TILES_VIEWER_JS if set; else <executable's
// folder>/../share/imr/imr-tiles-viewer.js (the build tree and an install). Empty when none.
std::filesystem::path FindTilesViewerScript();

// Where <model-viewer>'s UMD build is: $IMR_MODEL_VIEWER_JS if set; else
// <executable's folder>/../share/imr/model-viewer-umd.min.js (an install); else the copy
// tools/setup.sh put in the source tree's tools/node/node_modules. Empty when none exists.
std::filesystem::path FindModelViewerScript();

// Where the page's template is: $IMR_VIEWER_PAGE_TEMPLATE if set; else <executable's
// folder>/../share/imr/viewer_page.html (an install); else host/report/viewer_page.html in the
// source tree. Empty when none exists.
std::filesystem::path FindViewerPageTemplate();

// A glTF 2.0 file with external or data-URI buffers and images (PNG, JPEG: a texture atlas
// beside it) packed into one GLB (bytes); a .glb is returned as it is. Throws
// std::runtime_error naming the file when it cannot (not glTF 2.0, a missing buffer or image).
std::string ReadAsGlb(const std::filesystem::path& path);

}  // namespace imr::report
