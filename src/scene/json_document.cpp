#include "scene/json_document.hpp"

#include <set>
#include <string>
#include <utility>
#include <vector>

#include "kinema/error.hpp"

namespace kinema::scene_json {
namespace {

// Builds the document from the parser's events (SAX), keeping the path it is at: an error
// the JSON library finds (a number out of range, a syntax error) names its path, a repeated
// key is refused (the library would keep the last one silently), and so is nesting past
// kMaxDepth. Linear in the text: the library's own callback mode rescans each parent array
// whenever an element ends.
class DocumentBuilder : public nlohmann::json_sax<json> {
 public:
  static constexpr std::size_t kMaxDepth = 64;

  struct Stop {  // thrown to stop the parse; path() says where
    std::string what;
  };

  json document;

  bool null() override { return value(nullptr); }
  bool boolean(bool v) override { return value(v); }
  bool number_integer(number_integer_t v) override { return value(v); }
  bool number_unsigned(number_unsigned_t v) override { return value(v); }
  bool number_float(number_float_t v, const string_t&) override { return value(v); }
  bool string(string_t& v) override { return value(std::move(v)); }
  bool binary(binary_t& v) override { return value(json::binary(std::move(v))); }
  bool start_object(std::size_t) override { return open(json::object()); }
  bool start_array(std::size_t) override { return open(json::array()); }
  bool end_object() override { return close(); }
  bool end_array() override { return close(); }

  bool key(string_t& k) override {
    Frame& f = frames_.back();
    f.key = k;
    f.in_key = true;
    if (!f.keys.insert(k).second) throw Stop{"duplicate key (each key may appear once)"};
    f.slot = &(*f.node)[k];
    return true;
  }

  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception& e) override {
    // Without the library's "[json.exception.parse_error.101] " tag: where and what is the message.
    std::string what = e.what();
    if (const std::size_t tag_end = what.find("] "); what.starts_with("[json.exception.") && tag_end != std::string::npos) {
      what.erase(0, tag_end + 2);
    }
    throw Stop{"invalid JSON: " + what};
  }

  // Where the parser is: "forces[2].k", or "" at the top level.
  std::string path() const {
    std::string out;
    for (std::size_t i = 0; i < frames_.size(); ++i) {
      const Frame& f = frames_[i];
      if (f.node->is_object() && f.in_key) out += (out.empty() ? "" : ".") + f.key;
      if (!f.node->is_array()) continue;
      // The innermost array is reading its next element; an outer one, its last.
      const std::size_t index = f.node->size() - (i + 1 < frames_.size() ? 1 : 0);
      out += "[" + std::to_string(index) + "]";
    }
    return out;
  }

 private:
  struct Frame {
    json* node;
    json* slot = nullptr;  // objects: the value of the key being read
    std::string key;
    bool in_key = false;   // objects: reading the value of `key`
    std::set<std::string> keys;
  };

  // Where the next value goes: the document, the next array element, or the key's slot.
  json* place(json&& v) {
    if (frames_.empty()) return &(document = std::move(v));
    Frame& f = frames_.back();
    if (f.node->is_array()) {
      f.node->push_back(std::move(v));
      return &f.node->back();
    }
    *f.slot = std::move(v);
    return f.slot;
  }
  bool value(json&& v) {
    place(std::move(v));
    end_value();
    return true;
  }
  // A key names the path only until its value is complete.
  void end_value() {
    if (!frames_.empty() && frames_.back().node->is_object()) frames_.back().in_key = false;
  }
  bool open(json&& container) {
    if (frames_.size() == kMaxDepth) {
      throw Stop{"nested deeper than " + std::to_string(kMaxDepth) + " levels"};
    }
    json* node = place(std::move(container));
    frames_.push_back(Frame{node, nullptr, {}, false, {}});
    return true;
  }
  bool close() {
    frames_.pop_back();
    end_value();
    return true;
  }

  std::vector<Frame> frames_;
};

[[noreturn]] void invalid_json(std::string_view origin, const std::string& path,
                               const std::string& what) {
  throw Error(printable(std::string(origin) + ": " + (path.empty() ? "" : path + ": ") + what));
}

}  // namespace

json parse_json(std::string_view text, std::string_view origin) {
  if (const std::size_t nul = text.find('\0'); nul != std::string_view::npos) {
    invalid_json(origin, "", "invalid JSON: a NUL byte at offset " + std::to_string(nul));
  }
  DocumentBuilder builder;
  try {
    json::sax_parse(text.begin(), text.end(), &builder);
  } catch (const DocumentBuilder::Stop& stop) {
    invalid_json(origin, builder.path(), stop.what);
  }
  return std::move(builder.document);
}

}  // namespace kinema::scene_json
