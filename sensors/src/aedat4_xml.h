// The AEDAT 4.0 header's infoNode XML (dv config tree export), parsed for the AEDAT 4.0 reader
// (aedat4.cc). Internal to evio::sensors.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "byte_order.h"
#include "evio/calib/error.h"

namespace evio::detail::aedat4 {

// ---------------------------------------------------------------------------------------------
// infoNode XML (dv config tree export): <dv><node name="outInfo"><node name="0"><attr key=...>
// value</attr>...<node name="info"><attr key="sizeX">...</attr></node></node>...</node></dv>

struct XmlNode {
  std::string name;
  int parent = -1;
  std::map<std::string, std::string> attrs;  // <attr key="k">v</attr> children
};

inline std::string xml_unescape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] != '&') {
      out += s[i];
      continue;
    }
    const size_t semi = s.find(';', i);
    if (semi == std::string_view::npos || semi - i > 10) {
      out += s[i];
      continue;
    }
    const std::string_view ent = s.substr(i + 1, semi - i - 1);
    char c = 0;
    if (ent == "lt")
      c = '<';
    else if (ent == "gt")
      c = '>';
    else if (ent == "amp")
      c = '&';
    else if (ent == "quot")
      c = '"';
    else if (ent == "apos")
      c = '\'';
    else if (ent.size() >= 2 && ent[0] == '#') {
      long code = 0;
      bool ok = true;
      const bool hexa = ent[1] == 'x' || ent[1] == 'X';
      for (size_t k = hexa ? 2 : 1; k < ent.size() && ok; ++k) {
        const char d = ent[k];
        int v = -1;
        if (d >= '0' && d <= '9')
          v = d - '0';
        else if (hexa && d >= 'a' && d <= 'f')
          v = d - 'a' + 10;
        else if (hexa && d >= 'A' && d <= 'F')
          v = d - 'A' + 10;
        ok = v >= 0 && code < 0x10000;
        code = code * (hexa ? 16 : 10) + v;
      }
      if (ok && code > 0 && code < 128) c = static_cast<char>(code);
    }
    if (c == 0) {
      out += s[i];
      continue;
    }
    out += c;
    i = semi;
  }
  return out;
}

class XmlParser {
 public:
  XmlParser(std::string_view text, const std::string& path, int64_t file_offset)
      : s_(text), path_(path), file_offset_(file_offset) {}

  std::vector<XmlNode> parse() {
    std::vector<XmlNode> nodes;
    std::vector<int> stack;  // open <node> elements
    size_t i = 0;
    while ((i = s_.find('<', i)) != std::string_view::npos) {
      const size_t start = i;
      if (s_.compare(i, 4, "<!--") == 0) {
        i = skip_past(i, "-->");
        continue;
      }
      if (s_.compare(i, 2, "<?") == 0) {
        i = skip_past(i, "?>");
        continue;
      }
      if (s_.compare(i, 2, "<!") == 0) {
        i = skip_past(i, ">");
        continue;
      }
      if (s_.compare(i, 2, "</") == 0) {
        const size_t close = skip_past(i, ">");
        const std::string_view name = trim(s_.substr(i + 2, close - 1 - (i + 2)));
        if (name == "node") {
          if (stack.empty()) bad(start, "</node> without an open <node>");
          stack.pop_back();
        }
        i = close;
        continue;
      }
      // Start tag: name, attributes, optional '/'.
      size_t p = i + 1;
      const size_t name_begin = p;
      while (p < s_.size() && !is_space(s_[p]) && s_[p] != '>' && s_[p] != '/') ++p;
      const std::string_view tag = s_.substr(name_begin, p - name_begin);
      std::map<std::string, std::string> attrs;
      bool self_closing = false;
      for (;;) {
        while (p < s_.size() && is_space(s_[p])) ++p;
        if (p >= s_.size()) bad(start, "unterminated <" + std::string(tag) + "> tag");
        if (s_[p] == '>') {
          ++p;
          break;
        }
        if (s_[p] == '/') {
          if (p + 1 >= s_.size() || s_[p + 1] != '>')
            bad(start, "'/' not followed by '>' in <" + std::string(tag) + ">");
          self_closing = true;
          p += 2;
          break;
        }
        const size_t key_begin = p;
        while (p < s_.size() && !is_space(s_[p]) && s_[p] != '=' && s_[p] != '>' && s_[p] != '/') ++p;
        const std::string key(s_.substr(key_begin, p - key_begin));
        while (p < s_.size() && is_space(s_[p])) ++p;
        if (key.empty() || p >= s_.size() || s_[p] != '=')
          bad(start, "attribute without '=\"value\"' in <" + std::string(tag) + ">");
        ++p;
        while (p < s_.size() && is_space(s_[p])) ++p;
        if (p >= s_.size() || (s_[p] != '"' && s_[p] != '\''))
          bad(start, "unquoted attribute value in <" + std::string(tag) + ">");
        const char quote = s_[p++];
        const size_t value_end = s_.find(quote, p);
        if (value_end == std::string_view::npos)
          bad(start, "unterminated attribute value in <" + std::string(tag) + ">");
        attrs[key] = xml_unescape(s_.substr(p, value_end - p));
        p = value_end + 1;
      }
      if (tag == "node") {
        XmlNode n;
        n.name = attrs["name"];
        n.parent = stack.empty() ? -1 : stack.back();
        nodes.push_back(std::move(n));
        if (!self_closing) stack.push_back(static_cast<int>(nodes.size() - 1));
      } else if (tag == "attr") {
        std::string value;
        if (!self_closing) {
          const size_t end = s_.find("</", p);
          if (end == std::string_view::npos) bad(start, "<attr> without </attr>");
          value = xml_unescape(s_.substr(p, end - p));
          p = skip_past(end, ">");
        }
        if (!stack.empty()) nodes[static_cast<size_t>(stack.back())].attrs[attrs["key"]] = std::move(value);
      }
      i = p;
    }
    if (!stack.empty())
      bad(s_.size(), "<node name=\"" + nodes[static_cast<size_t>(stack.back())].name + "\"> is never closed");
    return nodes;
  }

 private:
  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }
  static std::string_view trim(std::string_view v) {
    while (!v.empty() && is_space(v.front())) v.remove_prefix(1);
    while (!v.empty() && is_space(v.back())) v.remove_suffix(1);
    return v;
  }
  size_t skip_past(size_t from, const char* token) const {
    const size_t at = s_.find(token, from + 1);
    if (at == std::string_view::npos) bad(from, std::string("markup without closing \"") + token + "\"");
    return at + std::strlen(token);
  }
  [[noreturn]] void bad(size_t at, const std::string& problem) const {
    throw InputError(
        path_, 0,
        "malformed infoNode XML at byte offset " + std::to_string(file_offset_ + static_cast<int64_t>(at)) + ": " + problem,
        "the dv config-tree XML: <node name=\"outInfo\"> with one <node name=\"<stream id>\"> per stream "
        "holding <attr key=\"typeIdentifier\"> and an info node with sizeX/sizeY");
  }

  std::string_view s_;
  const std::string& path_;
  int64_t file_offset_;
};

inline bool parse_int(const std::string& s, int64_t lo, int64_t hi, int64_t* out) {
  size_t i = 0;
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\n' || s[i] == '\r')) ++i;
  bool neg = false;
  if (i < s.size() && (s[i] == '-' || s[i] == '+')) neg = s[i++] == '-';
  if (i >= s.size()) return false;
  int64_t v = 0;
  for (; i < s.size() && s[i] >= '0' && s[i] <= '9'; ++i) {
    v = v * 10 + (s[i] - '0');
    if (v > (int64_t{1} << 40)) return false;
  }
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\n' || s[i] == '\r')) ++i;
  if (i != s.size()) return false;
  if (neg) v = -v;
  if (v < lo || v > hi) return false;
  *out = v;
  return true;
}

}  // namespace evio::detail::aedat4
