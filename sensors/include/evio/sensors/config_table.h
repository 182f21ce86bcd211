// One table per options struct: the YAML keys of a config section and, for each, the struct
// field it sets, its type, range and unit. The table alone drives
//   - reading (over whatever the struct holds before: the library's defaults, or a command's),
//     with unknown keys, wrong types and out-of-range values reported at file:line with the
//     expected form (yaml_config::Section),
//   - the range check of a struct value, check(): the struct's Validate calls it, so the library
//     and the YAML reader accept the same values, and Validate itself states only conditions
//     between fields,
//   - validation (the struct's own Validate after its keys are read),
//   - the resolved config: every key with the value used and a comment giving its unit and range,
//     readable again by the same table,
// so a key is declared once and every command that embeds the struct shares it. The tables of
// the library's options structs live beside the structs (<module>/option_tables.h).
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

  // A numeric key (integer, number or duration) as the YAML writes it: its range, and the
  // smallest change of the YAML value the field can hold (1 for integers, 1e-6 for durations
  // written in ms and held in ns, 0 for real numbers). Lets a test put every key just outside its
  // range and see both the reader and check() reject it.
  struct NumericKey {
    std::string key;  // dotted below sections
    Interval range;   // in the YAML's unit (ms for durations)
    double step;
    std::function<bool(T&, double)> set;  // the field from a YAML value, unchecked; false: the field's type cannot hold it
  };

  // what: the struct in error messages, e.g. "tracker settings" ("invalid tracker settings: ...").
  explicit Table(std::string what = "settings") : what_(std::move(what)) {}

  // ---- fields ---------------------------------------------------------------------------------------

  // An integer field of any integral type, in [lo, hi].
  template <class G>
  Table& integer(const std::string& key, G get, int64_t lo, int64_t hi) {
    using F = Field<G>;
    static_assert(std::is_integral_v<F>, "integer(): the field must be integral");
    const std::string expected = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    Entry e{key, expected};
    e.read = [get, lo, hi, expected](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      double v = 0;
      if (!n.IsScalar() || !parse_finite(n.Scalar(), &v) || v != std::floor(v) || v < static_cast<double>(lo) ||
          v > static_cast<double>(hi)) {
        s.parser().fail(n, s.key_path(k), "is not an integer in range" + scalar_text(n), expected);
      }
      std::invoke(get, t) = static_cast<F>(v);
    };
    e.write = [get](const T& t) { return std::to_string(field(get, t)); };
    e.check = [get, lo, hi, expected](const T& t, const std::string& k, std::string* why) {
      const F v = field(get, t);
      return integer_in(v, lo, hi) || out_of_range(why, k, std::to_string(v), expected);
    };
    e.numeric = leaf_numeric(Interval::closed(static_cast<double>(lo), static_cast<double>(hi)), 1,
                             [get](T& t, double v) {
                               if (!holds<F>(v)) return false;
                               std::invoke(get, t) = static_cast<F>(v);
                               return true;
                             });
    return add(std::move(e));
  }

  // A seed: an unsigned 64-bit integer.
  template <class G>
  Table& seed(const std::string& key, G get) {
    static_assert(std::is_same_v<Field<G>, uint64_t>, "seed(): the field must be uint64_t");
    Entry e{key, "an unsigned 64-bit integer"};
    e.read = [get](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      const std::string v = n.IsScalar() ? n.Scalar() : std::string();
      char* end = nullptr;
      errno = 0;
      const unsigned long long x = std::strtoull(v.c_str(), &end, 10);
      if (v.empty() || v[0] == '-' || end != v.c_str() + v.size() || errno == ERANGE) {
        s.parser().fail(n, s.key_path(k), "is not a seed" + scalar_text(n), "an unsigned 64-bit integer");
      }
      std::invoke(get, t) = x;
    };
    e.write = [get](const T& t) { return std::to_string(field(get, t)); };
    return add(std::move(e));
  }

  // A real number in r (a Range, or an Interval such as Interval::open_closed(0, 1)), in `unit`
  // (free text, e.g. "px", "rad/s"; empty: dimensionless). Finite; allow_infinity: ".inf" is a
  // value too (e.g. "no limit").
  template <class G>
  Table& number(const std::string& key, G get, const Interval& r, const std::string& unit, bool allow_infinity = false) {
    static_assert(std::is_same_v<Field<G>, double>, "number(): the field must be double");
    const std::string or_inf = allow_infinity ? " or .inf" : "";
    const std::string expected = r.number_text() + (unit.empty() ? "" : " (" + unit + ")") + or_inf;
    Entry e{key, describe(r, unit) + or_inf};
    e.read = [get, r, unit, allow_infinity](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      if (allow_infinity && n.IsScalar() && (n.Scalar() == ".inf" || n.Scalar() == "inf")) {
        std::invoke(get, t) = std::numeric_limits<double>::infinity();
        return;
      }
      std::invoke(get, t) = s.number_of(n, s.key_path(k), r, unit);
    };
    e.write = [get](const T& t) { return yaml_number(field(get, t)); };
    e.check = [get, r, allow_infinity, expected](const T& t, const std::string& k, std::string* why) {
      const double v = field(get, t);
      const bool ok = (std::isfinite(v) && r.contains(v)) || (allow_infinity && v == std::numeric_limits<double>::infinity());
      return ok || out_of_range(why, k, yaml_number(v), expected);
    };
    e.numeric = leaf_numeric(r, 0, [get](T& t, double v) {
      std::invoke(get, t) = v;
      return true;
    });
    return add(std::move(e));
  }

  // A duration held in ns (int64), written in ms in the YAML (keys end in _ms); r in ms.
  template <class G>
  Table& duration_ms(const std::string& key, G get, const Interval& r) {
    static_assert(std::is_same_v<Field<G>, int64_t>, "duration_ms(): the field must be int64_t ns");
    const std::string expected = r.number_text() + " (ms)";
    Entry e{key, describe(r, "ms")};
    e.read = [get, r](const Section& s, const std::string& k, T& t) {
      const double ms = s.number_of(s.get(k), s.key_path(k), r, "ms");
      if (std::abs(ms) > 9e12) s.parser().fail(s.get(k), s.key_path(k), "is too large", "ms below 9e12");
      std::invoke(get, t) = static_cast<int64_t>(std::llround(ms * 1e6));
    };
    e.write = [get](const T& t) { return yaml_number(static_cast<double>(field(get, t)) * 1e-6); };
    e.check = [get, r, expected](const T& t, const std::string& k, std::string* why) {
      const double ms = static_cast<double>(field(get, t)) * 1e-6;
      return r.contains(ms) || out_of_range(why, k, yaml_number(ms), expected);
    };
    e.numeric = leaf_numeric(r, 1e-6, [get](T& t, double ms) {
      if (!(std::abs(ms) <= 9e12)) return false;
      std::invoke(get, t) = static_cast<int64_t>(std::llround(ms * 1e6));
      return true;
    });
    return add(std::move(e));
  }

  // A duration held in seconds (double), written in ms in the YAML; r in ms.
  template <class G>
  Table& seconds_as_ms(const std::string& key, G get, const Interval& r) {
    static_assert(std::is_same_v<Field<G>, double>, "seconds_as_ms(): the field must be double s");
    const std::string expected = r.number_text() + " (ms)";
    Entry e{key, describe(r, "ms")};
    e.read = [get, r](const Section& s, const std::string& k, T& t) {
      std::invoke(get, t) = 1e-3 * s.number_of(s.get(k), s.key_path(k), r, "ms");
    };
    e.write = [get](const T& t) { return yaml_number(field(get, t) * 1e3); };
    e.check = [get, r, expected](const T& t, const std::string& k, std::string* why) {
      const double ms = field(get, t) * 1e3;
      return (std::isfinite(ms) && r.contains(ms)) || out_of_range(why, k, yaml_number(ms), expected);
    };
    e.numeric = leaf_numeric(r, 0, [get](T& t, double ms) {
      std::invoke(get, t) = 1e-3 * ms;
      return true;
    });
    return add(std::move(e));
  }

  template <class G>
  Table& boolean(const std::string& key, G get) {
    static_assert(std::is_same_v<Field<G>, bool>, "boolean(): the field must be bool");
    Entry e{key, "true or false"};
    e.read = [get](const Section& s, const std::string& k, T& t) { std::invoke(get, t) = s.boolean(k, false); };
    e.write = [get](const T& t) { return std::string(field(get, t) ? "true" : "false"); };
    return add(std::move(e));
  }

  // One of a list of names, each standing for a value of the field (an enum, usually).
  template <class G>
  Table& choice(const std::string& key, G get, std::vector<std::pair<std::string, Field<G>>> names) {
    using F = Field<G>;
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : " | ") + n.first;
    auto table = std::make_shared<const std::vector<std::pair<std::string, F>>>(std::move(names));
    Entry e{key, list};
    e.read = [get, table, list](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      const std::string v = n.IsScalar() ? n.Scalar() : std::string();
      for (const auto& [name, value] : *table) {
        if (n.IsScalar() && v == name) {
          std::invoke(get, t) = value;
          return;
        }
      }
      s.parser().fail(n, s.key_path(k), n.IsScalar() ? "'" + v + "' is not allowed" : "is not a string", list);
    };
    e.write = [get, table](const T& t) {
      const F& v = field(get, t);
      for (const auto& [name, value] : *table) {
        if (value == v) return name;
      }
      return std::string("?");
    };
    e.check = [get, table, list](const T& t, const std::string& k, std::string* why) {
      const F& v = field(get, t);
      for (const auto& nv : *table) {
        if (nv.second == v) return true;
      }
      return validation_failed(why, k + ": value " + value_text(v) + " has no name (expected: " + list + ")");
    };
    return add(std::move(e));
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
    Entry e{key, expected};
    e.read = [get, table, expected](const Section& s, const std::string& k, T& t) {
      const YAML::Node n = s.get(k);
      std::vector<std::string> words;
      if (n.IsSequence()) {
        for (const YAML::Node& w : n) words.push_back(w.IsScalar() ? w.Scalar() : std::string());
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
    };
    e.write = [get, table](const T& t) {
      std::string text;
      for (const V& v : field(get, t))
        for (const auto& [name, value] : *table)
          if (value == v) text += (text.empty() ? "" : ", ") + name;
      return "[" + text + "]";
    };
    e.check = [get, table, expected](const T& t, const std::string& k, std::string* why) {
      const std::vector<V>& values = field(get, t);
      if (values.empty()) return validation_failed(why, k + ": is empty (expected: " + expected + ")");
      for (size_t i = 0; i < values.size(); ++i) {
        const auto named = std::find_if(table->begin(), table->end(), [&](const auto& nv) { return nv.second == values[i]; });
        if (named == table->end())
          return validation_failed(why, k + ": value " + value_text(values[i]) + " has no name (expected: " + expected + ")");
        if (std::find(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(i), values[i]) != values.begin() + static_cast<std::ptrdiff_t>(i))
          return validation_failed(why, k + ": '" + named->first + "' is listed twice (expected: " + expected + ")");
      }
      return true;
    };
    return add(std::move(e));
  }

  // Three finite numbers, e.g. a vector in m/s^2.
  template <class G>
  Table& vector3(const std::string& key, G get, const std::string& unit) {
    static_assert(std::is_same_v<Field<G>, Eigen::Vector3d>, "vector3(): the field must be Eigen::Vector3d");
    Entry e{key, "[x, y, z]" + (unit.empty() ? std::string() : " (" + unit + ")")};
    e.read = [get, unit](const Section& s, const std::string& k, T& t) {
      std::invoke(get, t) = s.vec3(k, Eigen::Vector3d::Zero(), Range::kAny, unit);
    };
    e.write = [get](const T& t) { return vector3_text(field(get, t)); };
    e.check = [get, unit](const T& t, const std::string& k, std::string* why) {
      const Eigen::Vector3d& v = field(get, t);
      return v.allFinite() ||
             validation_failed(why, k + ": is not finite (" + vector3_text(v) + ") (expected: a list of 3 numbers" +
                                        (unit.empty() ? std::string() : " (" + unit + ")") + ")");
    };
    return add(std::move(e));
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
    entries_.push_back(Entry{key, {}});
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
      Entry e{prefix + se.key, se.expected};
      if (se.read) e.read = [get, f = se.read](const Section& s, const std::string& k, T& t) { f(s, k, std::invoke(get, t)); };
      if (se.write) e.write = [get, f = se.write](const T& t) { return f(field(get, t)); };
      if (se.section) {
        e.section = [get, f = se.section](const Section& s, T& t) { f(s, std::invoke(get, t)); };
        e.write_section = [get, f = se.write_section](std::ostream& y, const T& t, int indent) { f(y, field(get, t), indent); };
      }
      if (se.check) {
        e.check = [get, f = se.check](const T& t, const std::string& k, std::string* why) { return f(field(get, t), k, why); };
      }
      if (se.numeric) e.numeric = [get, f = se.numeric](const std::string& k) { return lift<S>(f(k), get); };
      entries_.push_back(std::move(e));
    }
    for (const auto& h : sub.present_) present_.push_back([get, h](T& t) { h(std::invoke(get, t)); });
    for (const auto& h : sub.finish_) finish_.push_back([get, h](const Section& s, T& t) { h(s, std::invoke(get, t)); });
    for (const auto& v : sub.validators_) {
      validators_.push_back({v.what, [get, f = v.check](const T& t, std::string* why) { return f(field(get, t), why); }});
    }
    return *this;
  }

  // A sub-map `key` read by `sub` over get(t).
  template <class S, class G>
  Table& section(const std::string& key, const Table<S>& sub, G get) {
    static_assert(std::is_same_v<Field<G>, S>, "section(): the accessor must return the table's struct");
    auto table = std::make_shared<const Table<S>>(sub);
    Entry e{key, {}};
    e.section = [get, table](const Section& s, T& t) { table->read(s, &std::invoke(get, t)); };
    e.write_section = [get, table](std::ostream& y, const T& t, int indent) { table->write(y, field(get, t), indent); };
    e.check = [get, table](const T& t, const std::string& k, std::string* why) {
      return table->check_keys(field(get, t), k + ".", why);
    };
    e.numeric = [get, table](const std::string& k) { return lift<S>(table->numeric_keys_at(k + "."), get); };
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
  // T::Validate after the keys are read; a failure names the section. (T::Validate may call
  // check(), which never runs the validators.)
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

  // True when every key's value in `value` is one the reader accepts: integers and numbers in
  // their range (numbers finite unless the key takes .inf), choices with a name, lists of choices
  // non-empty without repeats, vectors finite; sections and included tables key by key. Otherwise
  // false, and *why (when given) names the first key outside, its value and the expected form in
  // the reader's words: "rings: is out of range (17) (expected: an integer in [1, 16])".
  // Only the ranges: no validator runs (an options struct's Validate calls check() for its
  // fields' ranges and adds the conditions between fields).
  bool check(const T& value, std::string* why) const { return check_keys(value, "", why); }

  // Every integer, number and duration key, with sections' keys as "section.key".
  std::vector<NumericKey> numeric_keys() const { return numeric_keys_at(""); }

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
    Entry(std::string k, std::string x) : key(std::move(k)), expected(std::move(x)) {}
    std::string key;
    std::string expected;  // the comment in the resolved config
    std::function<void(const Section&, const std::string&, T&)> read;
    std::function<std::string(const T&)> write;
    std::function<void(const Section&, T&)> section;
    std::function<void(std::ostream&, const T&, int)> write_section;
    // The value against the key's range, the message naming the key as given; null: any value.
    std::function<bool(const T&, const std::string&, std::string*)> check;
    // The numeric keys under the key as given (one for a numeric field, a section's for a section).
    std::function<std::vector<NumericKey>(const std::string&)> numeric;
  };
  struct Validator {
    std::string what;
    std::function<bool(const T&, std::string*)> check;
  };

  // The field get names in t, read-only (accessors take T&, so const T& is cast for reading).
  template <class G>
  static const Field<G>& field(const G& get, const T& t) {
    return std::invoke(get, const_cast<T&>(t));
  }
  template <class F>
  static bool integer_in(F v, int64_t lo, int64_t hi) {
    if constexpr (std::is_signed_v<F>) {
      return static_cast<int64_t>(v) >= lo && static_cast<int64_t>(v) <= hi;
    } else {
      return hi >= 0 && static_cast<uint64_t>(v) <= static_cast<uint64_t>(hi) &&
             (lo <= 0 || static_cast<uint64_t>(v) >= static_cast<uint64_t>(lo));
    }
  }
  // True when the integral type F holds the whole number v.
  template <class F>
  static bool holds(double v) {
    const double top = std::ldexp(1.0, std::numeric_limits<F>::digits);  // 2^digits: just above the largest F
    return v == std::floor(v) && v < top && (std::is_signed_v<F> ? v >= -top : v >= 0);
  }
  template <class F>
  static std::string value_text(const F& v) {
    if constexpr (std::is_enum_v<F>) {
      return std::to_string(static_cast<long long>(v));
    } else if constexpr (std::is_arithmetic_v<F>) {
      return std::to_string(v);
    } else {
      return "?";
    }
  }
  static std::string vector3_text(const Eigen::Vector3d& v) {
    return "[" + yaml_number(v.x()) + ", " + yaml_number(v.y()) + ", " + yaml_number(v.z()) + "]";
  }
  static bool out_of_range(std::string* why, const std::string& key, const std::string& value, const std::string& expected) {
    return validation_failed(why, key + ": is out of range (" + value + ") (expected: " + expected + ")");
  }
  static std::string describe(const Interval& r, const std::string& unit) {
    const std::string range = r.text();
    if (unit.empty()) return range.empty() ? "a number" : range;
    return range.empty() ? unit : unit + ", " + range;
  }
  static std::string scalar_text(const YAML::Node& n) {
    return n.IsScalar() ? " ('" + n.Scalar() + "')" : std::string();
  }
  static std::function<std::vector<NumericKey>(const std::string&)> leaf_numeric(const Interval& r, double step,
                                                                                  std::function<bool(T&, double)> set) {
    return [r, step, set = std::move(set)](const std::string& k) { return std::vector<NumericKey>{{k, r, step, set}}; };
  }
  // Numeric keys of a table of S, as keys of T through get.
  template <class S, class G>
  static std::vector<NumericKey> lift(const std::vector<typename Table<S>::NumericKey>& keys, const G& get) {
    std::vector<NumericKey> out;
    for (const auto& n : keys) {
      out.push_back({n.key, n.range, n.step, [get, f = n.set](T& t, double v) { return f(std::invoke(get, t), v); }});
    }
    return out;
  }

  bool check_keys(const T& value, const std::string& prefix, std::string* why) const {
    for (const Entry& e : entries_) {
      if (e.check && !e.check(value, prefix + e.key, why)) return false;
    }
    return true;
  }
  std::vector<NumericKey> numeric_keys_at(const std::string& prefix) const {
    std::vector<NumericKey> out;
    for (const Entry& e : entries_) {
      if (!e.numeric) continue;
      for (NumericKey& n : e.numeric(prefix + e.key)) out.push_back(std::move(n));
    }
    return out;
  }

  // A later declaration of a key replaces an included one.
  Table& add(Entry e) {
    for (Entry& old : entries_) {
      if (old.key == e.key) {
        old = std::move(e);
        return *this;
      }
    }
    entries_.push_back(std::move(e));
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
