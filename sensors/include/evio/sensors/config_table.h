// One table per options struct: the YAML keys of a config section and, for each, the struct
// field it sets, its type, range and unit. The table alone drives
//   - reading (over whatever the struct holds before: the library's defaults, or a command's),
//     with unknown keys, wrong types and out-of-range values reported at file:line with the
//     expected form (yaml_config::Section),
//   - validation (the struct's own Validate after its keys are read),
//   - the resolved config: every key with the value used and a comment giving its unit and range,
//     readable again by the same table,
// so a key is declared once and every command that embeds the struct shares it.
//
//   Table<EfastOptions> t("eFAST settings");
//   t.boolean("filter_sae", &EfastOptions::filter_sae)
//    .duration_ms("filter_window_ms", &EfastOptions::filter_window_ns, Range::kNonNegative)
//    .validate();
//
// A field is named by a member pointer or by a lambda `[](T& t) -> F& { ... }` (for fields of
// nested structs). include() merges another struct's table into this section (same YAML map);
// section() nests one as a sub-map.
#pragma once

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <limits>
#include <memory>
#include <ostream>
#include <sstream>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "evio/sensors/yaml_config.h"

namespace evio::yaml_config {

// Shortest decimal text that reads back to exactly v ("0.1", not "0.10000000000000001");
// ".inf" / "-.inf" / ".nan" as YAML spells them.
inline std::string yaml_number(double v) {
  if (std::isnan(v)) return ".nan";
  if (std::isinf(v)) return v > 0 ? ".inf" : "-.inf";
  char buf[64];
  for (int precision = 1; precision <= 17; ++precision) {
    std::snprintf(buf, sizeof(buf), "%.*g", precision, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  // Plain decimals for ordinary magnitudes ("10", not "1e+01").
  if (std::string(buf).find('e') != std::string::npos && std::abs(v) >= 1e-4 && std::abs(v) < 1e15) {
    char fixed[64];
    for (int decimals = 0; decimals <= 20; ++decimals) {
      std::snprintf(fixed, sizeof(fixed), "%.*f", decimals, v);
      if (std::strtod(fixed, nullptr) == v) return fixed;
    }
  }
  return buf;
}

// True when the dotted path (e.g. "tracker.contrast_threshold") is set in the map s.
inline bool has_path(const Section& s, const std::string& dotted) {
  YAML::Node cur = YAML::Clone(s.node());
  for (const std::string& key : split_path(dotted)) {
    if (!cur.IsMap()) return false;
    const YAML::Node next = cur[key];
    if (!next || next.IsNull()) return false;
    cur = next;
  }
  return true;
}

template <class T>
class Table {
 public:
  // The type of the field an accessor (member pointer or lambda) names.
  template <class G>
  using Field = std::remove_cv_t<std::remove_reference_t<std::invoke_result_t<G, T&>>>;

  // what: the struct in error messages, e.g. "tracker settings" ("invalid tracker settings: ...").
  explicit Table(std::string what = "settings") : what_(std::move(what)) {}

  // ---- fields ---------------------------------------------------------------------------------------

  // An integer field of any integral type, in [lo, hi].
  template <class G>
  Table& integer(const std::string& key, G get, int64_t lo, int64_t hi) {
    using F = Field<G>;
    static_assert(std::is_integral_v<F>, "integer(): the field must be integral");
    const std::string expected = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    return add(key, expected, [get, lo, hi, expected](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      double v = 0;
      if (!n.IsScalar() || !parse_finite(n.Scalar(), &v) || v != std::floor(v) || v < static_cast<double>(lo) ||
          v > static_cast<double>(hi)) {
        s.parser().fail(n, s.key_path(k), "is not an integer in range" + scalar_text(n), expected);
      }
      std::invoke(get, t) = static_cast<F>(v);
    }, [get](const T& t) { return std::to_string(std::invoke(get, const_cast<T&>(t))); });
  }

  // A seed: an unsigned 64-bit integer.
  template <class G>
  Table& seed(const std::string& key, G get) {
    static_assert(std::is_same_v<Field<G>, uint64_t>, "seed(): the field must be uint64_t");
    return add(key, "an unsigned 64-bit integer", [get](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      const std::string v = n.IsScalar() ? n.Scalar() : std::string();
      char* end = nullptr;
      errno = 0;
      const unsigned long long x = std::strtoull(v.c_str(), &end, 10);
      if (v.empty() || v[0] == '-' || end != v.c_str() + v.size() || errno == ERANGE) {
        s.parser().fail(n, s.key_path(k), "is not a seed" + scalar_text(n), "an unsigned 64-bit integer");
      }
      std::invoke(get, t) = x;
    }, [get](const T& t) { return std::to_string(std::invoke(get, const_cast<T&>(t))); });
  }

  // A real number in range r, in `unit` (free text, e.g. "px", "rad/s"; empty: dimensionless).
  // allow_infinity: ".inf" is a value (e.g. "no limit").
  template <class G>
  Table& number(const std::string& key, G get, Range r, const std::string& unit, bool allow_infinity = false) {
    static_assert(std::is_same_v<Field<G>, double>, "number(): the field must be double");
    return add(key, describe(r, unit) + (allow_infinity ? " or .inf" : ""),
               [get, r, unit, allow_infinity](const Section& s, const std::string& k, T& t) {
                 const YAML::Node n = s.get(k);
                 if (allow_infinity && n.IsScalar() && (n.Scalar() == ".inf" || n.Scalar() == "inf")) {
                   std::invoke(get, t) = std::numeric_limits<double>::infinity();
                   return;
                 }
                 std::invoke(get, t) = s.number_of(n, s.key_path(k), r, unit);
               },
               [get](const T& t) { return yaml_number(std::invoke(get, const_cast<T&>(t))); });
  }

  // A duration held in ns (int64), written in ms in the YAML (keys end in _ms).
  template <class G>
  Table& duration_ms(const std::string& key, G get, Range r) {
    static_assert(std::is_same_v<Field<G>, int64_t>, "duration_ms(): the field must be int64_t ns");
    return add(key, describe(r, "ms"), [get, r](const Section& s, const std::string& k, T& t) {
      const double ms = s.number_of(s.get(k), s.key_path(k), r, "ms");
      if (std::abs(ms) > 9e12) s.parser().fail(s.get(k), s.key_path(k), "is too large", "ms below 9e12");
      std::invoke(get, t) = static_cast<int64_t>(std::llround(ms * 1e6));
    }, [get](const T& t) { return yaml_number(static_cast<double>(std::invoke(get, const_cast<T&>(t))) * 1e-6); });
  }

  // A duration held in seconds (double), written in ms in the YAML.
  template <class G>
  Table& seconds_as_ms(const std::string& key, G get, Range r) {
    static_assert(std::is_same_v<Field<G>, double>, "seconds_as_ms(): the field must be double s");
    return add(key, describe(r, "ms"), [get, r](const Section& s, const std::string& k, T& t) {
      std::invoke(get, t) = 1e-3 * s.number_of(s.get(k), s.key_path(k), r, "ms");
    }, [get](const T& t) { return yaml_number(std::invoke(get, const_cast<T&>(t)) * 1e3); });
  }

  template <class G>
  Table& boolean(const std::string& key, G get) {
    static_assert(std::is_same_v<Field<G>, bool>, "boolean(): the field must be bool");
    return add(key, "true or false", [get](const Section& s, const std::string& k, T& t) {
      std::invoke(get, t) = s.boolean(k, false);
    }, [get](const T& t) { return std::string(std::invoke(get, const_cast<T&>(t)) ? "true" : "false"); });
  }

  // One of a list of names, each standing for a value of the field (an enum, usually).
  template <class G>
  Table& choice(const std::string& key, G get, std::vector<std::pair<std::string, Field<G>>> names) {
    using F = Field<G>;
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : " | ") + n.first;
    auto table = std::make_shared<const std::vector<std::pair<std::string, F>>>(std::move(names));
    return add(key, list, [get, table, list](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      const std::string v = n.IsScalar() ? n.Scalar() : std::string();
      for (const auto& [name, value] : *table) {
        if (n.IsScalar() && v == name) {
          std::invoke(get, t) = value;
          return;
        }
      }
      s.parser().fail(n, s.key_path(k), n.IsScalar() ? "'" + v + "' is not allowed" : "is not a string", list);
    }, [get, table](const T& t) {
      const F& v = std::invoke(get, const_cast<T&>(t));
      for (const auto& [name, value] : *table) {
        if (value == v) return name;
      }
      return std::string("?");
    });
  }

  // A list of names from a fixed set, each standing for a value (a std::vector of an enum): a YAML
  // sequence ([flow, similarity]) or one comma-separated string ("flow,similarity"); at least one,
  // no repeats.
  template <class G>
  Table& choice_list(const std::string& key, G get, std::vector<std::pair<std::string, typename Field<G>::value_type>> names) {
    using V = typename Field<G>::value_type;
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : " | ") + n.first;
    const std::string expected = "a list of " + list + " (YAML sequence or comma-separated)";
    auto table = std::make_shared<const std::vector<std::pair<std::string, V>>>(std::move(names));
    return add(key, expected, [get, table, expected](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      std::vector<std::string> words;
      if (n.IsSequence()) {
        for (const YAML::Node& e : n) words.push_back(e.IsScalar() ? e.Scalar() : std::string());
      } else if (n.IsScalar()) {
        std::string w;
        for (char c : n.Scalar() + ",") {
          if (c == ',') {
            words.push_back(w), w.clear();
          } else if (c != ' ') {
            w += c;
          }
        }
      }
      std::vector<V> out;
      for (const std::string& w : words) {
        bool found = false;
        for (const auto& [name, value] : *table) {
          if (w == name) {
            if (std::find(out.begin(), out.end(), value) != out.end())
              s.parser().fail(n, s.key_path(k), "'" + w + "' is listed twice", expected);
            out.push_back(value);
            found = true;
          }
        }
        if (!found) s.parser().fail(n, s.key_path(k), "'" + w + "' is not allowed", expected);
      }
      if (out.empty()) s.parser().fail(n, s.key_path(k), "is empty", expected);
      std::invoke(get, t) = out;
    }, [get, table](const T& t) {
      std::string text;
      for (const V& v : std::invoke(get, const_cast<T&>(t)))
        for (const auto& [name, value] : *table)
          if (value == v) text += (text.empty() ? "" : ", ") + name;
      return "[" + text + "]";
    });
  }

  // Three numbers, e.g. a vector in m/s^2.
  template <class G>
  Table& vector3(const std::string& key, G get, const std::string& unit) {
    static_assert(std::is_same_v<Field<G>, Eigen::Vector3d>, "vector3(): the field must be Eigen::Vector3d");
    return add(key, "[x, y, z]" + (unit.empty() ? std::string() : " (" + unit + ")"),
               [get, unit](const Section& s, const std::string& k, T& t) {
                 std::invoke(get, t) = s.vec3(k, Eigen::Vector3d::Zero(), Range::kAny, unit);
               },
               [get](const T& t) {
                 const Eigen::Vector3d& v = std::invoke(get, const_cast<T&>(t));
                 return "[" + yaml_number(v.x()) + ", " + yaml_number(v.y()) + ", " + yaml_number(v.z()) + "]";
               });
  }

  // Adds a remark to a declared key's comment in the resolved config (e.g. what 0 means).
  Table& note(const std::string& key, const std::string& text) {
    for (Entry& e : entries_) {
      if (e.key == key) e.expected += "; " + text;
    }
    return *this;
  }

  // A key that is accepted and ignored (e.g. a free-text `description`); not written back.
  Table& ignored(const std::string& key) {
    Entry e;
    e.key = key;
    entries_.push_back(std::move(e));
    return *this;
  }

  // ---- composition ----------------------------------------------------------------------------------

  // Every key of `sub` (a table of the struct get(t) returns) in this same map, except `skip`.
  // prefix: put before each included key (e.g. "global_").
  template <class S, class G>
  Table& include(const Table<S>& sub, G get, const std::vector<std::string>& skip = {},
                 const std::string& prefix = {}) {
    static_assert(std::is_same_v<Field<G>, S>, "include(): the accessor must return the table's struct");
    for (const auto& se : sub.entries_) {
      if (std::find(skip.begin(), skip.end(), se.key) != skip.end()) continue;
      Entry e;
      e.key = prefix + se.key;
      e.expected = se.expected;
      if (se.read) e.read = [get, f = se.read](const Section& s, const std::string& k, T& t) { f(s, k, std::invoke(get, t)); };
      if (se.write) e.write = [get, f = se.write](const T& t) { return f(std::invoke(get, const_cast<T&>(t))); };
      if (se.section) {
        e.section = [get, f = se.section](const Section& s, T& t) { f(s, std::invoke(get, t)); };
        e.write_section = [get, f = se.write_section](std::ostream& y, const T& t, int indent) {
          f(y, std::invoke(get, const_cast<T&>(t)), indent);
        };
      }
      entries_.push_back(std::move(e));
    }
    for (const auto& h : sub.present_) present_.push_back([get, h](T& t) { h(std::invoke(get, t)); });
    for (const auto& h : sub.finish_) finish_.push_back([get, h](const Section& s, T& t) { h(s, std::invoke(get, t)); });
    for (const auto& v : sub.validators_) {
      validators_.push_back({v.what, [get, f = v.check](const T& t, std::string* why) {
                               return f(std::invoke(get, const_cast<T&>(t)), why);
                             }});
    }
    return *this;
  }

  // A sub-map `key` read by `sub` over get(t).
  template <class S, class G>
  Table& section(const std::string& key, const Table<S>& sub, G get) {
    static_assert(std::is_same_v<Field<G>, S>, "section(): the accessor must return the table's struct");
    Entry e;
    e.key = key;
    auto table = std::make_shared<const Table<S>>(sub);
    e.section = [get, table](const Section& s, T& t) { table->read(s, &std::invoke(get, t)); };
    e.write_section = [get, table](std::ostream& y, const T& t, int indent) {
      table->write(y, std::invoke(get, const_cast<T&>(t)), indent);
    };
    entries_.push_back(std::move(e));
    return *this;
  }

  // Run when the section is present in the YAML, before its keys are read (e.g. a filter section
  // that is there is enabled unless it says `enabled: false`).
  Table& on_present(std::function<void(T&)> f) {
    present_.push_back(std::move(f));
    return *this;
  }
  // Run after the section's keys are read (defaults that follow other keys), before validation.
  Table& finish(std::function<void(const Section&, T&)> f) {
    finish_.push_back(std::move(f));
    return *this;
  }
  // T::Validate after the keys are read; a failure names the section.
  Table& validate() {
    validators_.push_back({what_, [](const T& t, std::string* why) { return t.Validate(why); }});
    return *this;
  }
  Table& validate(std::function<bool(const T&, std::string*)> check) {
    validators_.push_back({what_, std::move(check)});
    return *this;
  }

  // ---- use ------------------------------------------------------------------------------------------

  // Reads the map s over *t (keys absent keep their value); throws evio::InputError.
  void read(const Section& s, T* t) const {
    std::vector<std::string> keys;
    for (const Entry& e : entries_) keys.push_back(e.key);
    s.allow(keys);
    for (const auto& h : present_) h(*t);
    for (const Entry& e : entries_) {
      if (!s.has(e.key)) continue;
      if (e.section) {
        e.section(s.child(e.key, false, "a map"), *t);
      } else if (e.read) {
        e.read(s, e.key, *t);
      }
    }
    for (const auto& h : finish_) h(s, *t);
    for (const Validator& v : validators_) {
      std::string why;
      if (!v.check(*t, &why)) s.fail("invalid " + v.what + ": " + why, "consistent settings");
    }
  }

  // Every key with its value, one per line at `indent` spaces, each with a comment giving the
  // expected form (unit and range); sub-sections as nested maps.
  void write(std::ostream& y, const T& t, int indent = 0) const {
    const std::string pad(static_cast<size_t>(indent), ' ');
    size_t width = 0;
    for (const Entry& e : entries_) {
      if (e.write) width = std::max(width, e.key.size() + 2 + e.write(t).size());
    }
    for (const Entry& e : entries_) {
      if (e.write_section) {
        y << pad << e.key << ":\n";
        e.write_section(y, t, indent + 2);
      } else if (e.write) {
        const std::string line = e.key + ": " + e.write(t);
        y << pad << line << std::string(width - line.size() + 2, ' ') << "# " << e.expected << "\n";
      }
    }
  }

  // The keys of this map, in order.
  std::vector<std::string> keys() const {
    std::vector<std::string> out;
    for (const Entry& e : entries_) out.push_back(e.key);
    return out;
  }

 private:
  template <class S>
  friend class Table;

  struct Entry {
    std::string key;
    std::string expected;
    std::function<void(const Section&, const std::string&, T&)> read;
    std::function<std::string(const T&)> write;
    std::function<void(const Section&, T&)> section;
    std::function<void(std::ostream&, const T&, int)> write_section;
  };
  struct Validator {
    std::string what;
    std::function<bool(const T&, std::string*)> check;
  };

  static std::string describe(Range r, const std::string& unit) {
    switch (r) {
      case Range::kPositive:
        return unit.empty() ? "> 0" : unit + ", > 0";
      case Range::kNonNegative:
        return unit.empty() ? ">= 0" : unit + ", >= 0";
      case Range::kUnit:
        return unit.empty() ? "in [0, 1]" : unit + ", in [0, 1]";
      default:
        return unit.empty() ? "a number" : unit;
    }
  }
  static std::string scalar_text(const YAML::Node& n) {
    return n.IsScalar() ? " ('" + n.Scalar() + "')" : std::string();
  }

  Table& add(const std::string& key, std::string expected,
             std::function<void(const Section&, const std::string&, T&)> read, std::function<std::string(const T&)> write) {
    for (Entry& e : entries_) {
      if (e.key == key) {  // a later declaration replaces an included one
        e = Entry{key, std::move(expected), std::move(read), std::move(write), {}, {}};
        return *this;
      }
    }
    entries_.push_back(Entry{key, std::move(expected), std::move(read), std::move(write), {}, {}});
    return *this;
  }

  std::string what_;
  std::vector<Entry> entries_;
  std::vector<std::function<void(T&)>> present_;
  std::vector<std::function<void(const Section&, T&)>> finish_;
  std::vector<Validator> validators_;
};

// Reads a command's config: the YAML file `path` (empty: none) with the command-line overrides
// `sets` ("key.sub=value") applied on top, through `table`, over `config` (the command's
// defaults). Errors name the file and line, or the --set option, with the expected form.
template <class T>
T read_config(const Table<T>& table, T config, const std::string& path, const std::vector<std::string>& sets,
              const std::string& expected) {
  YAML::Node root = path.empty() ? YAML::Node(YAML::NodeType::Map) : load_yaml_file(path, expected);
  if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  if (!root.IsMap()) throw InputError(path, 1, "the top level is not a map", expected);
  const std::vector<Override> applied = apply_set_overrides(root, sets);
  const Parser parser(path.empty() ? std::string("--set") : path, applied);
  try {
    table.read(Section(&parser, root, ""), &config);
  } catch (const YAML::Exception& e) {
    throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML error: " + e.msg, expected);
  }
  return config;
}

// The resolved config: `header` (comment lines) and every key of the table with its value.
template <class T>
std::string config_text(const Table<T>& table, const T& config, const std::string& header) {
  std::ostringstream y;
  y << header;
  table.write(y, config);
  return y.str();
}

}  // namespace evio::yaml_config
