// A test features plugin that holds the host to the SDK's promise on threads (imr/sdk/plugin.h):
// create, every call and destroy of an instance come from one thread. A call from another thread
// fails the sequence naming it; a destroy from another thread aborts the process. It tracks
// nothing (the run ends in "no surface was reconstructed"), so it runs fast.
#include <imr/sdk/plugin.hpp>

#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <thread>

namespace {

class ThreadCheckedFeatures : public imr::sdk::Features {
 public:
  static constexpr const char* kId = "org.imr.test.features.thread_checked";
  static constexpr const char* kVersion = "0.0.1";
  static constexpr const char* kDescription = "test: checks that one thread makes, calls and destroys it";
  static constexpr const char* kParamsSchema = R"({})";
  ThreadCheckedFeatures(const imr::sdk::Params&, const imr::sdk::Host&)
      : thread_(std::this_thread::get_id()) {}
  ~ThreadCheckedFeatures() override {
    if (std::this_thread::get_id() != thread_) {
      std::fprintf(stderr, "thread_checked: destroy on another thread than create\n");
      std::abort();
    }
  }
  std::span<const imr_track_observation> ProcessFrame(const imr_camera&, const imr_image_view&,
                                                     bool) override {
    if (std::this_thread::get_id() != thread_)
      throw std::runtime_error("thread_checked: process_frame on another thread than create");
    return {};
  }

 private:
  std::thread::id thread_;
};

}  // namespace

IMR_PLUGIN_EXPORT(ThreadCheckedFeatures)
