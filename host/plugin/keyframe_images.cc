#include "host/plugin/keyframe_images.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <stdexcept>

namespace imr::plugin {
namespace {

std::atomic<KeyframeImageStore*> g_current{nullptr};

uint64_t BytesOf(const io::Image& image) { return image.pixels.size(); }

std::string MiB(uint64_t bytes) {
  return std::to_string((bytes + (uint64_t{1} << 19)) >> 20) + " MiB";
}

}  // namespace

std::string KeyframeImageStoreOptions::Check() const {
  if (budget_bytes == 0) return "budget_bytes: expected > 0";
  return {};
}

KeyframeImageStore::KeyframeImageStore(std::vector<std::string> paths,
                                       const KeyframeImageStoreOptions& options)
    : paths_(std::move(paths)), options_(options), entries_(paths_.size()) {
  if (const std::string e = options_.Check(); !e.empty())
    throw std::invalid_argument("keyframe image store: " + e);
}

KeyframeImageStore::~KeyframeImageStore() = default;

imr_status KeyframeImageStore::Acquire(uint64_t index, imr_image_view* out, std::string* error) {
  if (out == nullptr) {
    *error = "keyframe image: no output view (null pointer)";
    return IMR_INVALID_ARGUMENT;
  }
  std::unique_lock lock(mutex_);
  if (index >= entries_.size()) {
    *error = "keyframe image " + std::to_string(index) + " is out of range: this export has " +
             std::to_string(entries_.size()) + " keyframe" + (entries_.size() == 1 ? "" : "s") +
             (entries_.empty() ? "" : " (0.." + std::to_string(entries_.size() - 1) + ")");
    return IMR_INVALID_ARGUMENT;
  }
  Entry& e = entries_[index];
  if (!e.image) {
    // Decode outside the lock would let two threads decode the same file; exports are rarely
    // parallel over one image, so keep it simple and hold the lock.
    const auto start = std::chrono::steady_clock::now();
    auto image = std::make_unique<io::Image>();
    try {
      *image = io::ReadImage(paths_[index]);
    } catch (const std::exception& ex) {
      *error = "keyframe image " + std::to_string(index) + ": " + ex.what();
      return IMR_ERROR;
    }
    const uint64_t need = BytesOf(*image);
    EvictLocked(need);
    uint64_t held = 0;
    for (const Entry& x : entries_)
      if (x.image && x.holds > 0) held += BytesOf(*x.image);
    if (held + need > options_.budget_bytes) {
      *error = "keyframe image " + std::to_string(index) + ": the plugin holds " + MiB(held) +
               " of keyframe images and this one needs " + MiB(need) + ", beyond the host's " +
               MiB(options_.budget_bytes) + " budget: release images it no longer needs";
      return IMR_ERROR;
    }
    e.image = std::move(image);
    bytes_ += need;
    stats_.peak_bytes = std::max(stats_.peak_bytes, bytes_);
    ++stats_.decodes;
    stats_.decode_seconds +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  } else if (e.holds == 0) {
    lru_.remove(index);
  }
  ++e.holds;
  ++stats_.requests;
  const io::Image& im = *e.image;
  *out = imr_image_view{};
  out->struct_size = sizeof(imr_image_view);
  out->width = im.width;
  out->height = im.height;
  out->channels = im.channels;
  out->stride_bytes = im.stride_bytes;
  out->pixels = im.pixels.data();
  return IMR_OK;
}

void KeyframeImageStore::Release(uint64_t index) {
  std::lock_guard lock(mutex_);
  if (index >= entries_.size()) return;
  Entry& e = entries_[index];
  if (e.holds == 0 || !e.image) return;
  if (--e.holds == 0) {
    lru_.push_back(index);
    EvictLocked(0);
  }
}

void KeyframeImageStore::ReleaseAll() {
  std::lock_guard lock(mutex_);
  for (std::size_t i = 0; i < entries_.size(); ++i) {
    if (entries_[i].holds > 0 && entries_[i].image) lru_.push_back(i);
    entries_[i].holds = 0;
  }
  EvictLocked(0);
}

void KeyframeImageStore::DropDecoded() {
  std::lock_guard lock(mutex_);
  EvictLocked(options_.budget_bytes);  // every released image
}

void KeyframeImageStore::EvictLocked(uint64_t need) {
  while (!lru_.empty() && bytes_ + need > options_.budget_bytes) {
    Entry& e = entries_[lru_.front()];
    lru_.pop_front();
    bytes_ -= BytesOf(*e.image);
    e.image.reset();
    ++stats_.evictions;
  }
}

KeyframeImageStoreStats KeyframeImageStore::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

uint64_t KeyframeImageStore::cached_bytes() const {
  std::lock_guard lock(mutex_);
  return bytes_;
}

ScopedKeyframeImages::ScopedKeyframeImages(KeyframeImageStore* store) : store_(store) {
  KeyframeImageStore* expected = nullptr;
  if (!g_current.compare_exchange_strong(expected, store))
    throw std::logic_error("keyframe images: a store is already installed");
}

ScopedKeyframeImages::~ScopedKeyframeImages() {
  if (store_ != nullptr) store_->ReleaseAll();
  g_current = nullptr;
}

KeyframeImageStore* CurrentKeyframeImages() { return g_current.load(); }

}  // namespace imr::plugin
