// Keyframe images for exporters (SDK 1.1, imr_host_services.keyframe_image): the host decodes a
// keyframe's image file when a plugin first asks for it, keeps it while the plugin holds it, and
// afterwards only while a byte budget has room (least recently used images go first). So an
// exporter that visits every keyframe twice (e.g. once to colour vertices, once to fill a texture
// atlas) decodes each image once when the sequence fits the budget, and memory stays bounded when
// it does not. The services reach the store that a ScopedKeyframeImages installed around the
// export call; outside such a call they fail with a message.
#pragma once

#include "host/io/image_io.h"

#include <imr/sdk/plugin.h>

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace imr::plugin {

struct KeyframeImageStoreOptions {
  // Decoded bytes kept at most: held images count, released ones are evicted (least recently
  // used first) to stay within it. Asking for an image that would take held bytes beyond it fails.
  // 128 MiB: ~90 KITTI-sized colour images. The whole drive's images stayed decoded at the final
  // export within 512 MiB (281 MB at 1,000 imr-synth frames: the drive's peak, issue 46); a
  // one-pass export (vertex colours) decodes each once whatever the budget, a textured one
  // decodes again the views that fell out before each atlas page asks for them (the pages go
  // last to first, then first to last, ...: the default job, 101 views and 4 pages, 170 decodes).
  uint64_t budget_bytes = uint64_t{128} << 20;

  // Empty when usable, else which field and why.
  std::string Check() const;
};

struct KeyframeImageStoreStats {
  int64_t requests = 0;     // successful keyframe_image calls
  int64_t decodes = 0;      // image files decoded
  int64_t evictions = 0;    // decoded images dropped to stay within the budget
  uint64_t peak_bytes = 0;  // most decoded bytes kept at once
  double decode_seconds = 0.0;
};

// The images of one export's keyframes, by index. Thread-safe.
class KeyframeImageStore {
 public:
  explicit KeyframeImageStore(std::vector<std::string> paths,
                              const KeyframeImageStoreOptions& options = {});
  ~KeyframeImageStore();

  std::size_t size() const { return paths_.size(); }

  // The service behind imr_host_services.keyframe_image: fills `out` and holds the image, or
  // returns a status with `*error` ("keyframe image 12 is out of range: this export has 10
  // keyframes (0..9)", "<path>: cannot decode ...").
  imr_status Acquire(uint64_t index, imr_image_view* out, std::string* error);
  // One hold less on `index` (a no-op when not held).
  void Release(uint64_t index);
  // Drops every hold (the end of an export call); decoded images stay cached within the budget.
  void ReleaseAll();
  // Frees every decoded image no plugin holds (between two export calls: an exporter that needs
  // the images for several formats keeps what it made of them, as org.imr.exporter.assimp does).
  void DropDecoded();

  KeyframeImageStoreStats stats() const;
  uint64_t cached_bytes() const;

 private:
  struct Entry {
    std::unique_ptr<io::Image> image;  // null: not decoded (or evicted)
    int holds = 0;
  };
  void EvictLocked(uint64_t need);

  std::vector<std::string> paths_;
  KeyframeImageStoreOptions options_;
  mutable std::mutex mutex_;
  std::vector<Entry> entries_;
  std::list<uint64_t> lru_;  // decoded, released images, least recently used first
  uint64_t bytes_ = 0;
  KeyframeImageStoreStats stats_;
};

// Routes the host services' keyframe_image / release_keyframe_image to `store` for its
// lifetime (one export call, or the exports after one keyframe), and releases every hold at the
// end. One at a time per process: nesting throws std::logic_error.
class ScopedKeyframeImages {
 public:
  explicit ScopedKeyframeImages(KeyframeImageStore* store);
  ~ScopedKeyframeImages();
  ScopedKeyframeImages(const ScopedKeyframeImages&) = delete;
  ScopedKeyframeImages& operator=(const ScopedKeyframeImages&) = delete;

 private:
  KeyframeImageStore* store_;
};

// The installed store, or nullptr (for host_services.cc).
KeyframeImageStore* CurrentKeyframeImages();

}  // namespace imr::plugin
