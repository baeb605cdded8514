#include "host/io/json_stream.h"

#include "host/util/input_file.h"

#include <fstream>
#include <stdexcept>
#include <vector>

namespace imr::io {
namespace {
using nlohmann::json;

// Nesting beyond kMaxJsonDepth (with the member it is in) or a number out of range: well-formed
// JSON that cannot be read; the message is complete but for the file name.
struct UnreadableJson : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Builds values from SAX events. Depth 0 is the top-level object; depth 1 its members; for a
// streamed array member, depth 2 are its elements, each built and delivered on its own.
using ElementAt = std::function<void(const std::string&, std::size_t, json&&, int64_t, int64_t)>;

class Streamer : public nlohmann::json_sax<json> {
 public:
  // `in`: the stream parsed, asked where an element begins and ends (the parser reads it one
  // character at a time, without looking ahead past a bracket).
  Streamer(const std::set<std::string>& streamed,
           const std::function<void(const std::string&, json&&)>& member, const ElementAt& element,
           std::istream* in)
      : streamed_(streamed), member_(member), element_(element), in_(in) {}

  bool null() override { return Value(json(nullptr)); }
  bool boolean(bool v) override { return Value(json(v)); }
  bool number_integer(number_integer_t v) override { return Value(json(v)); }
  bool number_unsigned(number_unsigned_t v) override { return Value(json(v)); }
  bool number_float(number_float_t v, const string_t&) override { return Value(json(v)); }
  bool string(string_t& v) override { return Value(json(std::move(v))); }
  bool binary(binary_t& v) override { return Value(json::binary(std::move(v))); }

  bool start_object(std::size_t) override {
    if (!in_top_ && !done_) {
      in_top_ = true;
      return true;
    }
    if (!Open(json::object())) return false;
    return true;
  }
  bool end_object() override {
    if (stack_.empty()) {  // the top-level object ends
      in_top_ = false;
      done_ = true;
      return true;
    }
    return Close();
  }
  bool start_array(std::size_t) override {
    if (!in_top_) throw std::runtime_error("the top level is not a JSON object");
    if (stack_.empty() && !streaming_ && streamed_.count(key_)) {
      streaming_ = true;  // elements are built one by one
      index_ = 0;
      return true;
    }
    return Open(json::array());
  }
  bool end_array() override {
    if (stack_.empty() && streaming_) {
      streaming_ = false;
      return true;
    }
    return Close();
  }
  bool key(string_t& k) override {
    if (stack_.empty()) {
      key_ = k;
      keys_seen_.insert(k);
    } else {
      keys_.back() = k;
    }
    return true;
  }
  bool parse_error(std::size_t position, const std::string& token,
                   const nlohmann::detail::exception& ex) override {
    // out_of_range.406: a number beyond a double (1e400) is not a syntax error; say where.
    if (ex.id == 406)
      throw UnreadableJson("number " + token + " at byte " + std::to_string(position) +
                    " is out of range (beyond a double)");
    throw std::runtime_error(ex.what());
  }

 private:
  // A scalar or a just-opened container goes to its parent, or is a finished top-level unit.
  bool Value(json&& v) {
    if (!in_top_) throw std::runtime_error("the top level is not a JSON object");
    if (stack_.empty()) {
      Deliver(std::move(v));
      return true;
    }
    json& parent = *stack_.back();
    if (parent.is_array())
      parent.push_back(std::move(v));
    else
      parent[keys_.back()] = std::move(v);
    return true;
  }
  bool Open(json&& container) {
    if (!in_top_) throw std::runtime_error("the top level is not a JSON object");
    if (stack_.size() + 1 >= kMaxJsonDepth)
      throw UnreadableJson((streaming_ ? key_ + "[" + std::to_string(index_) + "]" : key_) +
                    ": arrays and objects nested deeper than " + std::to_string(kMaxJsonDepth) +
                    " levels");
    if (stack_.empty()) {
      root_ = std::move(container);
      stack_.push_back(&root_);
      if (streaming_) begin_ = static_cast<int64_t>(in_->tellg()) - 1;  // at its bracket
    } else {
      json& parent = *stack_.back();
      json* child;
      if (parent.is_array()) {
        parent.push_back(std::move(container));
        child = &parent.back();
      } else {
        child = &(parent[keys_.back()] = std::move(container));
      }
      stack_.push_back(child);
    }
    keys_.emplace_back();
    return true;
  }
  bool Close() {
    stack_.pop_back();
    keys_.pop_back();
    if (stack_.empty()) Deliver(std::move(root_));
    return true;
  }
  void Deliver(json&& v) {
    if (streaming_) {
      const bool container = v.is_structured();
      element_(key_, index_++, std::move(v), container ? begin_ : -1,
               container ? static_cast<int64_t>(in_->tellg()) : -1);
    } else {
      member_(key_, std::move(v));
    }
    root_ = json();
  }

  const std::set<std::string>& streamed_;
  const std::function<void(const std::string&, json&&)>& member_;
  const ElementAt& element_;
  std::istream* in_;
  int64_t begin_ = -1;
  bool in_top_ = false;
  bool done_ = false;
  bool streaming_ = false;
  std::size_t index_ = 0;
  std::string key_;
  json root_;
  std::vector<json*> stack_;
  std::vector<std::string> keys_;

 public:
  std::set<std::string> keys_seen_;
};

}  // namespace

std::set<std::string> StreamJsonFile(const std::filesystem::path& file, const std::set<std::string>& streamed,
                    const std::function<void(const std::string&, nlohmann::json&&)>& member,
                    const std::function<void(const std::string&, std::size_t,
                                             nlohmann::json&&)>& element) {
  return StreamJsonFile(file, streamed, member,
                        [&](const std::string& key, std::size_t i, json&& e, int64_t, int64_t) {
                          element(key, i, std::move(e));
                        });
}

std::set<std::string> StreamJsonFile(
    const std::filesystem::path& file, const std::set<std::string>& streamed,
    const std::function<void(const std::string&, nlohmann::json&&)>& member,
    const std::function<void(const std::string&, std::size_t, nlohmann::json&&, int64_t, int64_t)>& element) {
  // The open rule: a FIFO or a device named as the file is refused by name, never waited on.
  InputStream in(file, "a JSON file");
  Streamer s(streamed, member, element, &in);
  try {
    nlohmann::json::sax_parse(in, &s);
  } catch (const std::ios_base::failure& e) {
    throw std::runtime_error(file.string() + ": cannot read: " + e.what());
  } catch (const UnreadableJson& e) {
    throw std::runtime_error(file.string() + ": " + e.what());
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(file.string() + ": malformed JSON: " + e.what());
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    if (what.rfind("[json.exception", 0) == 0)
      throw std::runtime_error(file.string() + ": malformed JSON (truncated or broken): " + what);
    if (what == "the top level is not a JSON object")
      throw std::runtime_error(file.string() + ": " + what);
    throw;
  }
  return s.keys_seen_;
}

}  // namespace imr::io
