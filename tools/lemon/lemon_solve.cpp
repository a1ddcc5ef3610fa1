// lemon_solve: solves the correction problems that `cellflip run --export-lp` writes (free
// MPS, see src/solvers/mps.rs) with LEMON 1.3.1's network simplex, timing `run()` only, so
// that our min-cost-flow solver (`cellflip solve FILE`) can be compared with a peer.
//
// The reader follows `mps::read` in src/solvers/mps.rs line for line: the same accepted
// entries, the same errors (with the 1-based line, 0 for the checks after the last line), and
// the same problem: candidates in item order (stable), the bins of the rows in file order,
// then one free bin [0, 1] per column without a bin row, in that order.
//
// Build: ./build.sh (g++ -O2 -std=c++17 lemon_solve.cpp -llemon -o lemon_solve).

#include <lemon/network_simplex.h>
#include <lemon/smart_graph.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace {

// ---------------------------------------------------------------------------------------------
// The problem, as `BoundedAssignment` holds it.

struct Problem {
    std::vector<uint32_t> item_start;  // items + 1 entries
    std::vector<uint32_t> cand_bin;
    std::vector<double> cand_cost;
    std::vector<uint32_t> lower, upper;  // per bin
    // Bins [0, row_bins) are the file's bin rows; each later one is the free bin [0, 1] of one
    // column without a bin row.
    size_t row_bins = 0;
    size_t items() const { return item_start.empty() ? 0 : item_start.size() - 1; }
    size_t bins() const { return lower.size(); }
};

struct MpsFile {
    Problem problem;
    std::optional<double> recorded_optimum;
};

struct MpsError {
    size_t line;
    std::string reason;
};

// ---------------------------------------------------------------------------------------------
// What Rust's `str` methods do, on UTF-8 bytes.

// Length of the Unicode White_Space character at s[i..] (as `char::is_whitespace`), or 0.
size_t whitespace_len(std::string_view s, size_t i) {
    unsigned char c = s[i];
    if (c == ' ' || (c >= 0x09 && c <= 0x0d)) return 1;
    auto at = [&](size_t j) -> unsigned char { return i + j < s.size() ? s[i + j] : 0; };
    if (c == 0xc2 && (at(1) == 0x85 || at(1) == 0xa0)) return 2;  // U+0085, U+00A0
    if (c == 0xe1 && at(1) == 0x9a && at(2) == 0x80) return 3;     // U+1680
    if (c == 0xe2 && at(1) == 0x80) {
        unsigned char d = at(2);
        // U+2000..U+200A, U+2028, U+2029, U+202F
        if ((d >= 0x80 && d <= 0x8a) || d == 0xa8 || d == 0xa9 || d == 0xaf) return 3;
    }
    if (c == 0xe2 && at(1) == 0x81 && at(2) == 0x9f) return 3;  // U+205F
    if (c == 0xe3 && at(1) == 0x80 && at(2) == 0x80) return 3;  // U+3000
    return 0;
}

// `str::split_whitespace`.
void split_whitespace(std::string_view s, std::vector<std::string_view>& out) {
    out.clear();
    size_t i = 0, start = std::string_view::npos;
    while (i < s.size()) {
        size_t w = whitespace_len(s, i);
        if (w) {
            if (start != std::string_view::npos) out.push_back(s.substr(start, i - start));
            start = std::string_view::npos;
            i += w;
        } else {
            if (start == std::string_view::npos) start = i;
            ++i;
        }
    }
    if (start != std::string_view::npos) out.push_back(s.substr(start));
}

// `str::trim`.
std::string_view trim(std::string_view s) {
    size_t b = 0;
    while (b < s.size()) {
        size_t w = whitespace_len(s, b);
        if (!w) break;
        b += w;
    }
    s = s.substr(b);
    // From the end: find the last non-whitespace character by a forward scan.
    size_t end = 0, i = 0;
    while (i < s.size()) {
        size_t w = whitespace_len(s, i);
        if (w) {
            i += w;
        } else {
            ++i;
            end = i;
        }
    }
    return s.substr(0, end);
}

bool starts_with(std::string_view s, std::string_view p) {
    return s.size() >= p.size() && s.compare(0, p.size(), p) == 0;
}

// `u64::from_str`: an optional '+', then one or more ASCII digits, no overflow.
std::optional<uint64_t> parse_u64(std::string_view s) {
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    if (s.empty()) return std::nullopt;
    uint64_t v = 0;
    for (char ch : s) {
        if (ch < '0' || ch > '9') return std::nullopt;
        uint64_t d = uint64_t(ch - '0');
        if (v > (UINT64_MAX - d) / 10) return std::nullopt;
        v = v * 10 + d;
    }
    return v;
}

// `f64::from_str` restricted to finite values: Sign? (Digit+ | Digit+ '.' Digit* |
// Digit* '.' Digit+) ([eE] Sign? Digit+)?, correctly rounded (glibc strtod is). The words
// inf, infinity and nan parse in Rust but are not finite, so they fail here as there.
std::optional<double> parse_finite_f64(std::string_view s) {
    size_t i = 0, n = s.size();
    auto digit = [&](size_t j) { return j < n && s[j] >= '0' && s[j] <= '9'; };
    if (i < n && (s[i] == '+' || s[i] == '-')) ++i;
    size_t int_digits = 0, frac_digits = 0;
    while (digit(i)) ++i, ++int_digits;
    if (i < n && s[i] == '.') {
        ++i;
        while (digit(i)) ++i, ++frac_digits;
    }
    if (int_digits + frac_digits == 0) return std::nullopt;
    if (i < n && (s[i] == 'e' || s[i] == 'E')) {
        ++i;
        if (i < n && (s[i] == '+' || s[i] == '-')) ++i;
        if (!digit(i)) return std::nullopt;
        while (digit(i)) ++i;
    }
    if (i != n) return std::nullopt;
    std::string z(s);
    double v = std::strtod(z.c_str(), nullptr);
    if (!std::isfinite(v)) return std::nullopt;
    return v;
}

// Rust's `{:?}` of a string, close enough for error messages.
std::string debug_str(std::string_view s) {
    std::string out = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') out += '\\';
        if (c == '\t') { out += "\\t"; continue; }
        if (c == '\r') { out += "\\r"; continue; }
        out += c;
    }
    return out + "\"";
}

// Rust's `{}` of an f64, for error messages: integers without a fraction, else the shortest
// digits that read back to the same value.
std::string display_f64(double v) {
    char buf[64];
    if (v == std::floor(v) && std::fabs(v) < 1e17) {
        std::snprintf(buf, sizeof buf, "%.0f", v);
        return buf;
    }
    for (int prec = 1; prec <= 17; ++prec) {
        std::snprintf(buf, sizeof buf, "%.*g", prec, v);
        if (std::strtod(buf, nullptr) == v) break;
    }
    return buf;
}

// ---------------------------------------------------------------------------------------------
// The reader: `mps::read`.

struct Column {
    uint32_t item;
    std::optional<uint32_t> bin;
    double cost;
};

struct BinRow {
    bool kind_e;
    std::optional<double> rhs;
    std::optional<double> range;
};

class Reader {
  public:
    size_t line = 0;
    std::string section;
    std::optional<double> recorded_optimum;
    size_t items = 0;
    std::vector<BinRow> bins;
    std::unordered_map<uint64_t, uint32_t> bin_of_name;
    std::vector<Column> columns;
    std::optional<std::string> last_column;

    [[noreturn]] void fail(const std::string& reason) const { throw MpsError{line, reason}; }

    double number(std::string_view s) const {
        auto v = parse_finite_f64(s);
        if (!v) fail(debug_str(s) + " is not a finite number");
        return *v;
    }

    static std::optional<uint64_t> index(std::string_view name, std::string_view prefix) {
        if (!starts_with(name, prefix)) return std::nullopt;
        return parse_u64(name.substr(prefix.size()));
    }

    uint32_t bin_row(std::string_view name) const {
        auto b = index(name, "bin");
        if (b) {
            auto it = bin_of_name.find(*b);
            if (it != bin_of_name.end()) return it->second;
        }
        fail("row " + debug_str(name) + " is not a declared bin row");
    }

    void comment(std::string_view c) {
        std::string_view t = trim(c);
        const std::string_view key = "optimal objective ";
        if (!starts_with(t, key)) return;
        std::vector<std::string_view> f;
        split_whitespace(t.substr(key.size()), f);
        if (!f.empty()) recorded_optimum = number(f[0]);
    }

    void entry(const std::vector<std::string_view>& f) {
        const std::string& s = section;
        if (s == "ROWS") {
            if (f.size() == 2 && f[0] == "N" && f[1] == "cost") return;
            if (f.size() == 2 && f[0] == "E" && starts_with(f[1], "item")) {
                if (index(f[1], "item") != std::optional<uint64_t>(uint64_t(items))) {
                    fail("item row " + debug_str(f[1]) + " out of order");
                }
                ++items;
                return;
            }
            if (f.size() == 2 && (f[0] == "E" || f[0] == "L")) {
                auto b = index(f[1], "bin");
                if (!b) fail("row " + debug_str(f[1]) + ": expected item<i> or bin<b>");
                bin_of_name[*b] = uint32_t(bins.size());
                bins.push_back(BinRow{f[0] == "E", std::nullopt, std::nullopt});
                return;
            }
        } else if (s == "COLUMNS") {
            if (f.size() >= 3 && f.size() % 2 == 1) {
                column(f);
                return;
            }
        } else if (s == "RHS") {
            if (f.size() == 3) {
                rhs(f[1], f[2]);
                return;
            }
        } else if (s == "RANGES") {
            if (f.size() == 3) {
                uint32_t b = bin_row(f[1]);
                double v = number(f[2]);
                bins[b].range = v;
                return;
            }
        } else if (s == "BOUNDS") {
            if (f.size() == 4 && f[0] == "UP" && f[3] == "1") return;
        }
        fail("unexpected entry in section " + debug_str(s));
    }

    void column(const std::vector<std::string_view>& f) {
        std::string_view name = f[0];
        if (!last_column || *last_column != name) {
            last_column = std::string(name);
            columns.push_back(Column{UINT32_MAX, std::nullopt, 0.0});
        }
        for (size_t j = 1; j + 1 < f.size(); j += 2) {
            std::string_view row = f[j];
            double value = number(f[j + 1]);
            if (row == "cost") {
                columns.back().cost = value;
                continue;
            }
            if (value != 1.0) {
                fail("coefficient " + display_f64(value) + " in row " + debug_str(row) +
                     ": expected 1");
            }
            auto item = index(row, "item");
            std::optional<uint32_t> bin;
            if (starts_with(row, "bin")) bin = bin_row(row);
            Column& c = columns.back();
            if (item && c.item == UINT32_MAX) {
                c.item = uint32_t(*item);  // `as u32`: truncates, as in Rust
            } else if (bin && !c.bin) {
                c.bin = *bin;
            } else {
                fail("column " + debug_str(name) + ": unexpected row " + debug_str(row));
            }
        }
    }

    void rhs(std::string_view row, std::string_view value) {
        double v = number(value);
        if (starts_with(row, "item")) {
            if (v != 1.0) {
                fail("item row " + debug_str(row) + " has right-hand side " + display_f64(v) +
                     ", expected 1");
            }
            return;
        }
        uint32_t b = bin_row(row);
        bins[b].rhs = v;
    }

    // `f64 as u32`: saturating (the values here are non-negative integers).
    static uint32_t as_u32(double v) {
        return v >= 4294967295.0 ? UINT32_MAX : uint32_t(v);
    }

    MpsFile finish() {
        line = 0;
        Problem p;
        p.row_bins = bins.size();
        for (const BinRow& r : bins) {
            double upper = r.rhs.value_or(0.0);
            double lower = r.kind_e ? upper : (r.range ? upper - std::fabs(*r.range) : 0.0);
            if (upper < 0.0 || lower < 0.0 || upper != std::trunc(upper) ||
                lower != std::trunc(lower)) {
                fail("bin bounds [" + display_f64(lower) + ", " + display_f64(upper) +
                     "] are not counts");
            }
            p.lower.push_back(as_u32(lower));
            p.upper.push_back(as_u32(upper));
        }
        for (const Column& c : columns) {
            if (size_t(c.item) >= items) {
                fail("a column has no declared item row (" + std::to_string(c.item) + ")");
            }
        }
        std::stable_sort(columns.begin(), columns.end(),
                         [](const Column& a, const Column& b) { return a.item < b.item; });
        p.item_start.assign(items + 1, 0);
        p.cand_bin.reserve(columns.size());
        p.cand_cost.reserve(columns.size());
        for (const Column& c : columns) {
            p.item_start[size_t(c.item) + 1] += 1;
            uint32_t bin;
            if (c.bin) {
                bin = *c.bin;
            } else {
                p.lower.push_back(0);
                p.upper.push_back(1);
                bin = uint32_t(p.lower.size() - 1);
            }
            p.cand_bin.push_back(bin);
            p.cand_cost.push_back(c.cost);
        }
        for (size_t i = 0; i < items; ++i) {
            if (p.item_start[i + 1] == 0) fail("item " + std::to_string(i) + " has no column");
            p.item_start[i + 1] += p.item_start[i];
        }
        return MpsFile{std::move(p), recorded_optimum};
    }
};

MpsFile read_mps(const std::string& text) {
    Reader r;
    std::vector<std::string_view> fields;
    std::string_view all(text);
    size_t pos = 0, n = 0;
    // `str::lines`: split at "\n", drop one "\r" before it, no empty last line after a final
    // "\n".
    while (pos < all.size()) {
        size_t nl = all.find('\n', pos);
        std::string_view line;
        if (nl == std::string_view::npos) {
            line = all.substr(pos);
            pos = all.size();
        } else {
            line = all.substr(pos, nl - pos);
            if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
            pos = nl + 1;
        }
        r.line = ++n;
        if (!line.empty() && line[0] == '*') {
            r.comment(line.substr(1));
        } else if (line.empty() || line[0] != ' ') {
            split_whitespace(line, fields);
            r.section = fields.empty() ? std::string() : std::string(fields[0]);
        } else {
            split_whitespace(line, fields);
            r.entry(fields);
        }
    }
    return r.finish();
}

// ---------------------------------------------------------------------------------------------
// Solving.

enum class Pivot { Block, First, Best, Altering };

const char* pivot_name(Pivot p) {
    switch (p) {
        case Pivot::Block: return "block";
        case Pivot::First: return "first";
        case Pivot::Best: return "best";
        case Pivot::Altering: return "altering";
    }
    return "?";
}

struct Options {
    Pivot pivot = Pivot::Block;
    std::optional<double> int_scale;
    unsigned repeat = 3;
    std::vector<std::string> files;
};

[[noreturn]] void usage(const char* why) {
    std::fprintf(stderr,
                 "lemon_solve: %s\n"
                 "usage: lemon_solve [--pivot block|first|best|altering] [--int-scale S] "
                 "[--repeat N] FILE.mps...\n",
                 why);
    std::exit(1);
}

Options parse_args(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i], value;
        bool has_value = false;
        auto eq = a.find('=');
        if (starts_with(a, "--") && eq != std::string::npos) {
            value = a.substr(eq + 1);
            a = a.substr(0, eq);
            has_value = true;
        }
        auto next = [&]() -> std::string {
            if (has_value) return value;
            if (i + 1 >= argc) usage((a + " needs a value").c_str());
            return argv[++i];
        };
        if (a == "--pivot") {
            std::string v = next();
            if (v == "block") o.pivot = Pivot::Block;
            else if (v == "first") o.pivot = Pivot::First;
            else if (v == "best") o.pivot = Pivot::Best;
            else if (v == "altering") o.pivot = Pivot::Altering;
            else usage(("unknown pivot rule " + v).c_str());
        } else if (a == "--int-scale") {
            std::string v = next();
            auto s = parse_finite_f64(v);
            if (!s || *s <= 0.0) usage(("--int-scale " + v + ": expected a positive number").c_str());
            o.int_scale = *s;
        } else if (a == "--repeat") {
            std::string v = next();
            auto r = parse_u64(v);
            if (!r || *r == 0 || *r > 1000000) usage(("--repeat " + v + ": expected 1 or more").c_str());
            o.repeat = unsigned(*r);
        } else if (a == "-h" || a == "--help") {
            usage("help");
        } else if (starts_with(a, "--")) {
            usage(("unknown option " + a).c_str());
        } else {
            o.files.push_back(a);
        }
    }
    if (o.files.empty()) usage("no file given");
    return o;
}

using Graph = lemon::SmartDigraph;

struct Network {
    Graph g;
    std::vector<Graph::Arc> cand_arc;  // per candidate, item -> bin (or -> F)
    std::vector<Graph::Arc> bin_arc;   // per bin row, bin -> T
    std::optional<Graph::Arc> free_arc;  // F -> T, when some column has no bin row
    Graph::ArcMap<int> lower{g}, upper{g};
    Graph::NodeMap<int> supply{g};
};

// The network: items (supply 1), one node per bin row, F, T (supply -items); item -> bin
// [0, 1] per candidate, bin -> T [lower, upper] per bin row. The columns without a bin row
// (each with a free bin [0, 1] of its own in the problem read) go to one shared node F with
// F -> T [0, items]: the same flows and optimum, since each such column is an arc of capacity 1
// anyway. (With a node and a [0, 1] arc per such column, block search on double costs stalled
// on dam-2d band exact-paths step 40.) Bounds are capped at items + 1, which changes nothing:
// at most `items` units reach a bin, and a lower bound above that stays infeasible.
void build(const Problem& p, Network& net) {
    size_t n = p.items(), m = p.cand_bin.size(), nr = p.row_bins;
    if (n + nr + 2 >= size_t(INT_MAX) || m + nr + 1 >= size_t(INT_MAX)) {
        std::fprintf(stderr, "lemon_solve: problem too large for int indices\n");
        std::exit(1);
    }
    bool has_free = p.bins() > nr;
    Graph& g = net.g;
    g.reserveNode(int(n + nr + 2));
    g.reserveArc(int(m + nr + 1));
    std::vector<Graph::Node> item(n), bin(nr);
    for (auto& v : item) v = g.addNode();
    for (auto& v : bin) v = g.addNode();
    Graph::Node t = g.addNode();
    Graph::Node f = has_free ? g.addNode() : t;
    for (auto v : item) net.supply[v] = 1;
    for (auto v : bin) net.supply[v] = 0;
    net.supply[t] = -int(n);
    if (has_free) net.supply[f] = 0;
    net.cand_arc.resize(m);
    for (size_t i = 0; i < n; ++i) {
        for (size_t k = p.item_start[i]; k < p.item_start[i + 1]; ++k) {
            uint32_t b = p.cand_bin[k];
            Graph::Arc a = g.addArc(item[i], b < nr ? bin[b] : f);
            net.cand_arc[k] = a;
            net.lower[a] = 0;
            net.upper[a] = 1;
        }
    }
    uint64_t cap = uint64_t(n) + 1;
    net.bin_arc.resize(nr);
    for (size_t b = 0; b < nr; ++b) {
        Graph::Arc a = g.addArc(bin[b], t);
        net.bin_arc[b] = a;
        net.lower[a] = int(std::min<uint64_t>(p.lower[b], cap));
        net.upper[a] = int(std::min<uint64_t>(p.upper[b], cap));
    }
    if (has_free) {
        Graph::Arc a = g.addArc(f, t);
        net.free_arc = a;
        net.lower[a] = 0;
        net.upper[a] = int(n);
    }
}

struct Solved {
    std::vector<double> ms;
    std::vector<int> flow;  // per arc id, of the last run
    bool ok = true;
    const char* status = "";
};

template <typename Cost>
Solved solve(const Network& net, const Graph::ArcMap<Cost>& cost, Pivot pivot, unsigned repeat) {
    using NS = lemon::NetworkSimplex<Graph, int, Cost>;
    typename NS::PivotRule rule = NS::BLOCK_SEARCH;
    switch (pivot) {
        case Pivot::Block: rule = NS::BLOCK_SEARCH; break;
        case Pivot::First: rule = NS::FIRST_ELIGIBLE; break;
        case Pivot::Best: rule = NS::BEST_ELIGIBLE; break;
        case Pivot::Altering: rule = NS::ALTERING_LIST; break;
    }
    Solved s;
    for (unsigned r = 0; r < repeat; ++r) {
        NS ns(net.g);
        ns.lowerMap(net.lower).upperMap(net.upper).costMap(cost).supplyMap(net.supply);
        auto t0 = std::chrono::steady_clock::now();
        typename NS::ProblemType result = ns.run(rule);
        auto t1 = std::chrono::steady_clock::now();
        s.ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        if (result != NS::OPTIMAL) {
            s.ok = false;
            s.status = result == NS::INFEASIBLE ? "INFEASIBLE" : "UNBOUNDED";
            return s;
        }
        if (r + 1 == repeat) {
            s.flow.assign(size_t(net.g.maxArcId() + 1), 0);
            for (Graph::ArcIt a(net.g); a != lemon::INVALID; ++a) s.flow[size_t(net.g.id(a))] = ns.flow(a);
        }
    }
    return s;
}

// Checks the flow (each item one unit on one arc, each bin within its bounds) and returns
// the chosen candidate per item; an empty string when all is well, else what is wrong.
std::string check(const Problem& p, const Network& net, const std::vector<int>& flow,
                  std::vector<uint32_t>& choice) {
    size_t n = p.items();
    std::vector<uint64_t> load(p.bins(), 0);
    choice.assign(n, 0);
    for (size_t i = 0; i < n; ++i) {
        int units = 0;
        for (size_t k = p.item_start[i]; k < p.item_start[i + 1]; ++k) {
            int f = flow[size_t(net.g.id(net.cand_arc[k]))];
            if (f != 0 && f != 1) return "item " + std::to_string(i) + " sends " + std::to_string(f) + " on one arc";
            if (f == 1) {
                choice[i] = uint32_t(k);
                load[p.cand_bin[k]] += 1;
            }
            units += f;
        }
        if (units != 1) return "item " + std::to_string(i) + " sends " + std::to_string(units) + " units";
    }
    uint64_t free_load = 0;
    for (size_t b = 0; b < p.bins(); ++b) {
        if (load[b] < p.lower[b] || load[b] > p.upper[b]) {
            return "bin " + std::to_string(b) + " holds " + std::to_string(load[b]) + ", outside [" +
                   std::to_string(p.lower[b]) + ", " + std::to_string(p.upper[b]) + "]";
        }
        if (b >= p.row_bins) {
            free_load += load[b];
        } else if (uint64_t(flow[size_t(net.g.id(net.bin_arc[b]))]) != load[b]) {
            return "bin " + std::to_string(b) + ": flow to the sink differs from its load";
        }
    }
    if (net.free_arc && uint64_t(flow[size_t(net.g.id(*net.free_arc))]) != free_load) {
        return "the free bins' flow to the sink differs from their load";
    }
    return "";
}

double median(std::vector<double> v) {  // as crate::metrics::median: the upper middle
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
    Options o = parse_args(argc, argv);
    for (const std::string& path : o.files) {
        std::ifstream in(path, std::ios::binary);
        if (!in) {
            std::fprintf(stderr, "lemon_solve: %s: cannot read\n", path.c_str());
            return 1;
        }
        std::ostringstream buf;
        buf << in.rdbuf();
        MpsFile file;
        try {
            file = read_mps(buf.str());
        } catch (const MpsError& e) {
            std::fprintf(stderr, "lemon_solve: %s: line %zu: %s\n", path.c_str(), e.line,
                         e.reason.c_str());
            return 1;
        }
        const Problem& p = file.problem;
        std::printf("file %s: %zu items, %zu candidates, %zu bins\n", path.c_str(), p.items(),
                    p.cand_bin.size(), p.bins());
        std::fflush(stdout);

        Network net;
        build(p, net);
        Solved s;
        std::string label = pivot_name(o.pivot);
        if (o.int_scale) {
            double scale = *o.int_scale;
            char sbuf[64];
            std::snprintf(sbuf, sizeof sbuf, ", int-scale %g", scale);
            label += sbuf;
            // Potentials stay within [0, max/2]: keep every path's cost far below that.
            double max_abs = 0.0;
            for (double c : p.cand_cost) max_abs = std::max(max_abs, std::fabs(c * scale));
            double nodes = double(p.items() + p.bins() + 2);
            if (max_abs * nodes >= 0x1p61) {
                std::fprintf(stderr,
                             "lemon_solve: %s: --int-scale %g too large (largest scaled cost "
                             "%.3e over %.0f nodes would overflow 64-bit costs)\n",
                             path.c_str(), scale, max_abs, nodes);
                return 1;
            }
            Graph::ArcMap<long long> cost(net.g, 0);
            for (size_t k = 0; k < p.cand_cost.size(); ++k) {
                cost[net.cand_arc[k]] = std::llround(p.cand_cost[k] * scale);
            }
            s = solve<long long>(net, cost, o.pivot, o.repeat);
        } else {
            Graph::ArcMap<double> cost(net.g, 0.0);
            for (size_t k = 0; k < p.cand_cost.size(); ++k) cost[net.cand_arc[k]] = p.cand_cost[k];
            s = solve<double>(net, cost, o.pivot, o.repeat);
        }
        if (!s.ok) {
            std::fprintf(stderr, "lemon_solve: %s: lemon network simplex (%s): %s\n", path.c_str(),
                         label.c_str(), s.status);
            return 2;
        }
        std::vector<uint32_t> choice;
        std::string bad = check(p, net, s.flow, choice);
        if (!bad.empty()) {
            std::fprintf(stderr, "lemon_solve: %s: lemon network simplex (%s): bad flow: %s\n",
                         path.c_str(), label.c_str(), bad.c_str());
            return 3;
        }
        double objective = 0.0;  // in item order, as BoundedAssignment::objective
        for (uint32_t k : choice) objective += p.cand_cost[k];
        char rec[64] = "none", gap[64] = "none";
        if (file.recorded_optimum) {
            double r = *file.recorded_optimum;
            std::snprintf(rec, sizeof rec, "%.12e", r);
            std::snprintf(gap, sizeof gap, "%.1e", std::fabs(objective - r) / std::max(1.0, std::fabs(r)));
        }
        std::printf(
            "lemon network simplex (%s): solve ms %.3f (median of %u), objective %.12e, "
            "recorded %s, rel gap %s\n",
            label.c_str(), median(s.ms), o.repeat, objective, rec, gap);
        std::fflush(stdout);
    }
    return 0;
}
