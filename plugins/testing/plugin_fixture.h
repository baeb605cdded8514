// A test fixture for one built plugin library: loads it the way the host does (Boost.DLL,
// RTLD_NOW), takes its first descriptor, and tells how creating an instance with given params
// ends. Shared by the plugins' own tests.
#pragma once

#include <gtest/gtest.h>
#include <imr/sdk/host.hpp>
#include <imr/sdk/plugin.h>

#include <boost/dll/shared_library.hpp>

#include <string>

namespace imr::testing {

class PluginFixture : public ::testing::Test {
 protected:
  // Loads `library` and sets d_ to its first descriptor (asserts there is one).
  void LoadPlugin(const std::string& library) {
    lib_.load(library, boost::dll::load_mode::rtld_now);
    entry_ = lib_.get<const imr_plugin_descriptor*(uint32_t)>("imr_plugin_entry");
    d_ = entry_(0);
    ASSERT_NE(d_, nullptr);
  }

  // IMR_OK when an instance can be created with `params`, else the status and the message.
  imr_status CreateStatus(const std::string& params, std::string* message) {
    try {
      imr::sdk::Instance inst(d_, params, nullptr);
      return IMR_OK;
    } catch (const imr::sdk::PluginCallError& e) {
      *message = e.what();
      return e.status();
    }
  }

  boost::dll::shared_library lib_;
  const imr_plugin_descriptor* (*entry_)(uint32_t) = nullptr;
  const imr_plugin_descriptor* d_ = nullptr;
};

}  // namespace imr::testing
