// dsm-lookup: answers shadow queries against a deep shadow map, one answer
// line per query line, as a batch job or as a coprocess a renderer holds a
// pipe to. Documentation, including the streaming protocol: docs/dsm-lookup.md.
//
// Two query modes: a filtered point lookup (batched through a
// dsm::ShadowSystem), and with --area-light a soft shadow of an area light
// (dsm::SoftShadowContext). Queries already waiting are answered together, up
// to kBatchQueries; before a read that may wait, everything read is answered.
//
// Uses only libdsm's public API; the line parsing and printing are the tool's.
#include <array>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "dsm/area_light.h"
#include "dsm/error.h"
#include "dsm/lookup.h"
#include "area_light_size.h"
#include "map_json.h"
#include "dsm/reader.h"
#include "dsm/shadow_system.h"
#include "dsm/soft_shadow.h"
#include "dsm/span.h"
#include "dsm/tile_cache.h"
#include "query_line.h"
#include "option_checks.h"
#include "tool_support.h"

namespace {

using namespace dsm::tools;

constexpr const char* kToolName = "dsm-lookup";
constexpr const char* kDocumentation = "docs/dsm-lookup.md";
/// The process-wide cache's budget (tile_cache.h), used unless --cache-mb says otherwise.
constexpr double kDefaultCacheMiB = 256.0;
/// Keeps the byte count well inside size_t.
constexpr double kMaxCacheMiB = 1024.0 * 1024.0;
/// The widest map a reader accepts (ReaderOptions::maxWidth): a wider filter
/// only costs time, and an unbounded one would make a lookup loop for ages.
constexpr double kMaxFilterWidth = 131072.0;
/// Depths and thresholds in light units: any finite scene fits well inside.
constexpr double kMaxLength = 1e30;
/// Light samples per soft query: a bound keeps one query's time finite
/// (256 samples already put the estimate's noise below 1/32).
constexpr int kMaxLightSamples = 65536;
/// Most queries answered together: enough to amortise a batched lookup, few
/// enough that answers to a long input start flowing at once.
constexpr std::size_t kBatchQueries = 4096;

enum class Space { World, Light, Raster };
enum class Format { Csv, Json };
/// Where the complaint about a bad query goes (--errors): standard error, the
/// answer stream (so a client reading one pipe sees everything), or nowhere.
enum class ErrorReport { Stderr, Inline, Quiet };

struct Options {
    std::string map;
    std::string input;  ///< empty: standard input unless --point is given
    std::vector<std::string> points;
    std::string space = "world";
    std::string filter = "box";
    double filterWidth = 1.0;
    std::string level = "auto";
    std::string bias = "auto";
    std::optional<double> biasValue;  ///< --bias parsed; unset: automatic
    std::string format = "csv";
    bool header = false;
    bool errorBound = false;
    bool strict = false;
    bool stats = false;
    std::string errors = "stderr";
    double cacheMiB = kDefaultCacheMiB;
    // Soft shadows (--area-light); the rest apply only with it.
    std::string areaLight;  ///< empty: point lookups
    int lightSamples = 64;
    int layers = 0;
    double zThreshold = 0.0;
    std::uint64_t seed = 1;
    std::string soft = "mtsm";
};

/// Thrown for an argument CLI11 accepted but that does not make sense.
struct UsageError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// ---------------------------------------------------------------------------
// Parsing arguments (query lines: query_line.h)

/// --area-light disk:R or rect:W,H, through the library's parser.
dsm::AreaLightSize parseAreaLight(const std::string& text) {
    try {
        return dsm::parseAreaLightSize(text);
    } catch (const dsm::Error&) {
        throw UsageError("--area-light " + quotedInput(text) +
                         ": expected disk:R or rect:W,H with sizes > 0 (light-space units)");
    }
}

/// "X,Y,Z" of --point.
std::array<double, 3> parsePointArgument(const std::string& text) {
    const ParsedLine parsed = parseQueryLine(text);
    if (parsed.kind != ParsedLine::Kind::Point || text.find('#') != std::string::npos)
        throw UsageError("--point " + quotedInput(text) + ": expected three finite numbers X,Y,Z");
    return parsed.point;
}

// ---------------------------------------------------------------------------
// Query modes: how a point becomes an answer.

struct Answer {
    std::array<double, 3> v{1.0, 1.0, 1.0};
    double errorBound = 0.0;
    // Soft queries only (dsm::SoftShadowResult).
    int rays = 0;
    bool classifiedLit = false;
    double blockerDepth = 0.0;
    double filterWidth = 0.0;
};

using Point = std::array<double, 3>;

/// What became of one query's point: its answer, or what answering it threw.
struct Outcome {
    Answer answer;
    std::exception_ptr failure;
};

class QueryMode {
public:
    virtual ~QueryMode() = default;
    /// Throws dsm::Error: ErrorCode::argument when the point is at fault,
    /// another code when the map is.
    virtual Answer answer(const Point& point) = 0;

    /// Answers points[i] into outcomes[i] in order (both spans have the same
    /// size), possibly stopping after the first that fails; returns how many
    /// outcomes it filled, at least one. A failure holds what answer() throws
    /// for that point. This one answers point by point and stops at a failure,
    /// so that no query past one that may end the run is worked on.
    virtual std::size_t answerAll(dsm::Span<const Point> points, dsm::Span<Outcome> outcomes) {
        for (std::size_t i = 0; i < points.size(); ++i) {
            try {
                outcomes[i] = Outcome{answer(points[i]), nullptr};
            } catch (...) {
                outcomes[i] = Outcome{Answer{}, std::current_exception()};
                return i + 1;
            }
        }
        return points.size();
    }
};

/// A filtered lookup at the point: many at once through a dsm::ShadowSystem;
/// one at a time (answer()) through a dsm::LookupContext of the same map,
/// whose exceptions say why a point failed.
class PointLookup final : public QueryMode {
public:
    PointLookup(std::shared_ptr<dsm::ShadowSystem> system, const dsm::MapHandle* map, Space space,
                const dsm::LookupOptions& options)
        : system_(std::move(system)), map_(map), thread_(system_->createThread()), context_(system_->map(map)),
          space_(space), options_(options) {}

    Answer answer(const Point& p) override {
        dsm::LookupResult r;
        switch (space_) {
            case Space::World: r = context_.world(p, options_); break;
            case Space::Light: r = context_.light(p, options_); break;
            case Space::Raster: r = context_.raster(p[0], p[1], p[2], options_); break;
        }
        return Answer{r.v, r.errorBound};
    }

    std::size_t answerAll(dsm::Span<const Point> points, dsm::Span<Outcome> outcomes) override {
        results_.resize(points.size());
        const std::size_t failures = system_->lookup(*thread_, map_, lookupSpace(), points, options_, results_);
        for (std::size_t i = 0; i < points.size(); ++i) {
            const dsm::LookupResult& r = results_[i];
            // A failed point holds the failure value, which an answer may hold
            // too: such points are looked up once more, one at a time, to tell
            // them apart and to learn why they fail.
            if (failures > 0 && isFailureValue(r)) QueryMode::answerAll(points.subspan(i, 1), outcomes.subspan(i, 1));
            else outcomes[i] = Outcome{Answer{r.v, r.errorBound}, nullptr};
        }
        return points.size();
    }

private:
    dsm::LookupSpace lookupSpace() const {
        switch (space_) {
            case Space::World: return dsm::LookupSpace::world;
            case Space::Light: return dsm::LookupSpace::light;
            case Space::Raster: break;
        }
        return dsm::LookupSpace::raster;
    }

    /// The value of a failed lookup (shadow_system.h): lit with no confidence.
    static bool isFailureValue(const dsm::LookupResult& r) {
        return r.v == Point{1.0, 1.0, 1.0} && r.errorBound == 1.0 && r.pixelsUsed == 0;
    }

    std::shared_ptr<dsm::ShadowSystem> system_;
    const dsm::MapHandle* map_;
    std::unique_ptr<dsm::ShadowThread> thread_;
    dsm::LookupContext context_;
    Space space_;
    dsm::LookupOptions options_;
    std::vector<dsm::LookupResult> results_;
};

enum class SoftMethod { Mtsm, Pcf };

/// The fraction of an area light seen from the point: rays traced through the
/// map (SoftShadowContext::visibility) or the PCF baseline (pcfVisibility).
class SoftShadowQuery final : public QueryMode {
public:
    SoftShadowQuery(std::shared_ptr<const dsm::SoftShadowTracer> tracer, Space space, SoftMethod method,
                    const dsm::SoftShadowOptions& options)
        : light_(tracer->light()), context_(std::move(tracer)), space_(space), method_(method), options_(options) {}

    Answer answer(const Point& p) override {
        // The library takes world points; light space is one affine map away.
        const dsm::Vec3 receiver = space_ == Space::Light ? light_.lightToWorld(p) : p;
        const dsm::SoftShadowResult r = method_ == SoftMethod::Mtsm ? context_.visibility(receiver, options_)
                                                                    : context_.pcfVisibility(receiver, options_);
        Answer a;
        a.v = r.v;
        a.rays = r.rays;
        a.classifiedLit = r.classifiedLit;
        a.blockerDepth = r.blockerDepth;
        a.filterWidth = r.filterWidth;
        return a;
    }

    const dsm::SoftShadowStats& stats() const { return context_.stats(); }

private:
    dsm::AreaLight light_;
    dsm::SoftShadowContext context_;
    Space space_;
    SoftMethod method_;
    dsm::SoftShadowOptions options_;
};

// ---------------------------------------------------------------------------
// Output

/// Shortest %g text with enough digits (9) to read back as the same float.
std::string number(double v) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.9g", v);
    return buffer;
}

/// What JSON answers add after the values.
enum class Details { None, Traced, Pcf };

/// Prints one answer line per query, buffered; flush() hands them over.
class AnswerWriter {
public:
    /// `errorColumn`: CSV rows end in an error column (--errors inline),
    /// empty for an answer.
    AnswerWriter(Format format, int channels, bool errorBound, Details details = Details::None,
                 bool errorColumn = false)
        : format_(format), channels_(channels), errorBound_(errorBound), details_(details),
          errorColumn_(errorColumn && format == Format::Csv) {}

    void header() {
        if (format_ != Format::Csv) return;
        text_ += channels_ == 3 ? "r,g,b" : "v";
        if (errorBound_) text_ += ",error_bound";
        if (errorColumn_) text_ += ",error";
        text_ += '\n';
    }

    /// `key` is "line" or "point" (JSON only), `index` its number.
    void answer(const char* key, std::uint64_t index, const Answer& a) {
        if (format_ == Format::Csv) {
            text_ += number(a.v[0]);
            if (channels_ == 3) text_ += "," + number(a.v[1]) + "," + number(a.v[2]);
            if (errorBound_) text_ += "," + number(a.errorBound);
            if (errorColumn_) text_ += ',';
        } else {
            text_ += "{\"" + std::string(key) + "\":" + std::to_string(index);
            if (channels_ == 3)
                text_ += ",\"r\":" + number(a.v[0]) + ",\"g\":" + number(a.v[1]) + ",\"b\":" + number(a.v[2]);
            else
                text_ += ",\"v\":" + number(a.v[0]);
            if (errorBound_) text_ += ",\"error_bound\":" + number(a.errorBound);
            if (details_ == Details::Traced)
                text_ += ",\"rays\":" + std::to_string(a.rays) +
                         ",\"classified_lit\":" + (a.classifiedLit ? "true" : "false");
            if (details_ == Details::Pcf)
                text_ += ",\"blocker_depth\":" + number(a.blockerDepth) +
                         ",\"filter_width\":" + number(a.filterWidth);
            text_ += '}';
        }
        text_ += '\n';
    }

    /// The placeholder that keeps answers aligned with queries: nan in every
    /// CSV column (and "<key> N: problem" in the error column), or
    /// {"line":N,"error":"..."} (`key` as for answer()).
    void bad(const char* key, std::uint64_t index, const std::string& problem) {
        if (format_ == Format::Csv) {
            const int columns = (channels_ == 3 ? 3 : 1) + (errorBound_ ? 1 : 0);
            for (int c = 0; c < columns; ++c) text_ += c ? ",nan" : "nan";
            if (errorColumn_) text_ += "," + csvQuoted(oneLine(std::string(key) + " " + std::to_string(index) + ": " +
                                                               problem));
        } else {
            const nlohmann::json message = problem;
            text_ += "{\"" + std::string(key) + "\":" + std::to_string(index) + ",\"error\":" +
                     message.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "}";
        }
        text_ += '\n';
    }

    /// Writes what is buffered; false when standard output failed.
    bool flush() {
        if (!text_.empty()) {
            std::cout.write(text_.data(), static_cast<std::streamsize>(text_.size()));
            text_.clear();
        }
        std::cout.flush();
        return static_cast<bool>(std::cout);
    }

private:
    /// A CSV field in double quotes, inner quotes doubled.
    static std::string csvQuoted(const std::string& text) {
        std::string out = "\"";
        for (char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
        return out + '"';
    }

    Format format_;
    int channels_;
    bool errorBound_;
    Details details_;
    bool errorColumn_;
    std::string text_;
};

// ---------------------------------------------------------------------------
// The run

struct Totals {
    std::uint64_t queries = 0;  ///< answered or bad
    std::uint64_t bad = 0;
};

/// Why a run stopped early.
enum class Stop { None, Strict, MapError, InputError, OutputError };

std::string lineError(const std::string& inputName, std::uint64_t line, const std::string& problem) {
    return oneLine(std::string(kToolName) + ": ERROR '" + inputName + "' line " + std::to_string(line) + ": " +
                   problem);
}

class Session {
public:
    Session(const Options& o, std::string mapPath, QueryMode& mode, AnswerWriter& writer)
        : options_(o), mapPath_(std::move(mapPath)), mode_(mode), writer_(writer) {}

    Stop points(const std::vector<Point>& points) {
        for (std::size_t k = 0; k < points.size(); ++k) pending_.push_back(Query{k + 1, points[k], std::nullopt});
        const Stop stop = answerPending("point", [](std::uint64_t index, const std::string& problem) {
            // Arguments were checked; only a point the lookup itself refuses gets here.
            return oneLine(std::string(kToolName) + ": ERROR: --point " + std::to_string(index) + ": " + problem);
        });
        if (stop != Stop::None) return stop;
        return writer_.flush() ? Stop::None : Stop::OutputError;
    }

    Stop lines(std::streambuf& in, const std::string& inputName) {
        const auto complaint = [&inputName](std::uint64_t line, const std::string& problem) {
            return lineError(inputName, line, problem);
        };
        LineReader reader(in);
        std::string text;
        bool tooLong = false;
        std::uint64_t lineNumber = 0;
        for (;;) {
            // Before a read that may wait, what was read is answered and handed over.
            if (!reader.inputWaiting()) {
                if (const Stop stop = answerPending("line", complaint); stop != Stop::None) return stop;
                if (!writer_.flush()) return Stop::OutputError;
            }
            if (!reader.next(text, tooLong)) break;
            ++lineNumber;
            ParsedLine parsed;
            if (tooLong) {
                parsed.kind = ParsedLine::Kind::Bad;
                parsed.problem = "longer than " + std::to_string(kMaxLineBytes) + " bytes";
            } else {
                parsed = parseQueryLine(text);
            }
            if (parsed.kind == ParsedLine::Kind::Skip) continue;
            Query& query = pending_.emplace_back();
            query.index = lineNumber;
            if (parsed.kind == ParsedLine::Kind::Bad) query.problem = std::move(parsed.problem);
            else query.point = parsed.point;
            // Under --strict a bad line ends the run: nothing after it is read.
            if (pending_.size() >= kBatchQueries || (query.problem && options_.strict))
                if (const Stop stop = answerPending("line", complaint); stop != Stop::None) return stop;
        }
        if (const Stop stop = answerPending("line", complaint); stop != Stop::None) return stop;
        return writer_.flush() ? Stop::None : Stop::OutputError;
    }

    Totals totals;

private:
    /// A query read but not answered yet: its line (or --point) number, and
    /// its point or what is wrong with its line.
    struct Query {
        std::uint64_t index = 0;
        Point point{};
        std::optional<std::string> problem;
    };

    /// Answers the pending queries in order, their points all at once: an
    /// answer line each, or for a bad query its placeholder, then its
    /// complaint (complaint(index, problem)). Throws on a map problem, after
    /// the answers before it.
    template <class Complaint>
    Stop answerPending(const char* key, const Complaint& complaint) {
        const std::vector<Query> queries = std::move(pending_);
        pending_.clear();
        points_.clear();
        for (const Query& query : queries)
            if (!query.problem) points_.push_back(query.point);
        outcomes_.resize(points_.size());
        const dsm::Span<const Point> points(points_);
        const dsm::Span<Outcome> outcomes(outcomes_);
        std::size_t done = 0;  // points with an outcome
        std::size_t next = 0;  // the point of the next query that has one
        for (const Query& query : queries) {
            ++totals.queries;
            std::optional<std::string> problem = query.problem;
            if (!problem) {
                if (next == done) done += mode_.answerAll(points.subspan(done), outcomes.subspan(done));
                const Outcome& outcome = outcomes[next++];
                if (!outcome.failure) {
                    writer_.answer(key, query.index, outcome.answer);
                    continue;
                }
                problem = queryProblem(outcome.failure);
            }
            ++totals.bad;
            writer_.bad(key, query.index, *problem);
            // The answer line goes out before the complaint, so a reader of
            // both streams sees them in order.
            if (!writer_.flush()) return Stop::OutputError;
            complain(complaint(query.index, *problem));
            if (options_.strict) return Stop::Strict;
        }
        return Stop::None;
    }

    /// Why a point has no answer: a point or option out of range is the
    /// query's problem; anything else (a damaged or unreadable map) is
    /// rethrown and stops the run.
    static std::string queryProblem(const std::exception_ptr& failure) {
        try {
            std::rethrow_exception(failure);
        } catch (const dsm::Error& e) {
            if (e.code() != dsm::ErrorCode::argument) throw;
            return e.what();
        }
    }

    /// A bad query's error line, on standard error with --errors stderr only
    /// (inline put it in the answer already; quiet drops it).
    void complain(const std::string& line) const {
        if (options_.errors == "stderr") std::cerr << line << '\n';
    }

    const Options& options_;
    std::string mapPath_;
    QueryMode& mode_;
    AnswerWriter& writer_;
    std::vector<Query> pending_;
    std::vector<Point> points_;     // of the pending queries that have one
    std::vector<Outcome> outcomes_;  // of points_
};

Space spaceFromName(const std::string& name) {
    if (name == "light") return Space::Light;
    if (name == "raster") return Space::Raster;
    return Space::World;
}

/// Nothing for "auto", else the level.
std::optional<double> biasFromText(const std::string& text) {
    if (text == "auto") return std::nullopt;
    const std::optional<double> bias = parseNumber(text);
    if (!bias) throw UsageError("--bias: expected auto or a finite number, got " + quotedInput(text));
    return bias;
}

std::optional<unsigned> levelFromText(const std::string& text) {
    if (text == "auto") return std::nullopt;
    int level = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), level);
    if (error != std::errc() || end != text.data() + text.size() || level < 0)
        throw UsageError("--level: expected auto or a level number >= 0, got " + quotedInput(text));
    return static_cast<unsigned>(level);
}

std::string percent(std::uint64_t part, std::uint64_t whole) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.1f%%", whole ? 100.0 * double(part) / double(whole) : 0.0);
    return buffer;
}

void printStats(const Totals& totals, double seconds, const dsm::TileCacheStats& c) {
    const double perSecond = seconds > 0.0 ? double(totals.queries) / seconds : 0.0;
    char rate[64];
    std::snprintf(rate, sizeof rate, "%.6g s, %.6g queries/s", seconds, perSecond);
    std::cerr << kToolName << ": stats: " << totals.queries << " queries (" << totals.bad << " bad) in " << rate
              << '\n'
              << kToolName << ": stats: cache " << c.hits << " hits, " << c.misses << " misses ("
              << percent(c.hits, c.hits + c.misses) << " hits), " << c.tilesRead << " tiles read (" << c.bytesRead
              << " bytes), " << c.duplicateReads << " read twice, " << c.waits << " waits, " << c.evictions
              << " evictions, peak " << c.peakBytesInUse << " of " << c.budgetBytes << " bytes in use\n";
}

void printSoftStats(const dsm::SoftShadowStats& s, std::size_t hierarchyTiles) {
    std::cerr << kToolName << ": stats: soft " << s.queries << " queries (" << s.classifiedLit
              << " classified lit), " << s.rays << " rays (" << s.raysProvenOpaque << " ended by the umbra early-out), "
              << s.nodesVisited << " nodes, " << s.pixelsVisited << " pixels, " << s.samplesHit << " samples hit, "
              << hierarchyTiles << " tiles in the hierarchy\n";
}

/// The statistics of printStats and printSoftStats (`soft` null for point
/// lookups) as one JSON object on one line, for --format json.
void printStatsJson(const Totals& totals, double seconds, const dsm::TileCacheStats& c,
                    const dsm::SoftShadowStats* soft, std::size_t hierarchyTiles) {
    nlohmann::ordered_json stats{
        {"queries", totals.queries},
        {"bad", totals.bad},
        {"seconds", seconds},
        {"queries_per_second", seconds > 0.0 ? double(totals.queries) / seconds : 0.0},
        {"cache",
         {{"hits", c.hits},
          {"misses", c.misses},
          {"tiles_read", c.tilesRead},
          {"bytes_read", c.bytesRead},
          {"read_twice", c.duplicateReads},
          {"waits", c.waits},
          {"evictions", c.evictions},
          {"peak_bytes", c.peakBytesInUse},
          {"budget_bytes", c.budgetBytes}}}};
    if (soft)
        stats["soft"] = {{"queries", soft->queries},
                         {"classified_lit", soft->classifiedLit},
                         {"rays", soft->rays},
                         {"rays_proven_opaque", soft->raysProvenOpaque},
                         {"nodes", soft->nodesVisited},
                         {"pixels", soft->pixelsVisited},
                         {"samples_hit", soft->samplesHit},
                         {"hierarchy_tiles", hierarchyTiles}};
    std::cerr << nlohmann::ordered_json{{"stats", stats}}.dump() << '\n';
}

/// The options that belong to one query mode only.
void checkSoftOptions(const CLI::App& app, const Options& o) {
    const auto given = [&app](const char* name) { return app.count(name) > 0; };
    if (o.areaLight.empty()) {
        for (const char* name : {"--light-samples", "--layers", "--z-threshold", "--seed", "--soft"})
            if (given(name)) throw UsageError(std::string(name) + " applies only with --area-light");
        return;
    }
    parseAreaLight(o.areaLight);
    for (const char* name : {"--filter", "--filter-width", "--level"})
        if (given(name)) throw UsageError(std::string(name) + " does not apply to --area-light queries");
    if (o.errorBound) throw UsageError("--error-bound does not apply to --area-light queries");
    if (o.space == "raster")
        throw UsageError("--area-light takes world or light points, not --space raster");
    if (o.biasValue && *o.biasValue < 0.0) throw UsageError("--bias: must be >= 0 with --area-light");
    // The PCF baseline traces no rays and reads every layer through its filter.
    if (o.soft == "pcf")
        for (const char* name : {"--light-samples", "--layers", "--seed"})
            if (given(name)) throw UsageError(std::string(name) + " does not apply to --soft pcf");
}

int run(const Options& o, const std::vector<std::array<double, 3>>& points, std::optional<unsigned> level) {
    const bool queriesFromStdin = o.input == "-" || (o.input.empty() && points.empty());
    if (o.map == "-" && queriesFromStdin)
        throw UsageError("the map and the queries cannot both come from standard input");

    std::ifstream inputFile;
    std::string inputName = "<stdin>";
    std::unique_ptr<InputFile> mapFile;
    std::shared_ptr<dsm::ShadowSystem> system;
    const dsm::MapHandle* handle = nullptr;
    std::shared_ptr<const dsm::DeepShadowMap> map;
    // Errors about the map name it as the user did: "<stdin>" for standard input.
    const std::string mapName = o.map == "-" ? "<stdin>" : o.map;
    DisplayNames displayNames;
    try {
        mapFile = std::make_unique<InputFile>(o.map);
        addDisplayName(displayNames, *mapFile);
        dsm::ShadowSystemOptions systemOptions;
        systemOptions.cacheBytes = static_cast<std::size_t>(o.cacheMiB * 1024.0 * 1024.0);
        systemOptions.maxOpenFiles = 1;
        system = dsm::ShadowSystem::create(systemOptions);
        handle = system->open(mapFile->path());
        map = system->map(handle);
    } catch (const std::exception& e) {
        reportException(kToolName, e, mapName, displayNames);
        return kExitFailure;
    }
    if (!o.input.empty() && o.input != "-") {
        std::error_code ignored;
        if (std::filesystem::is_directory(o.input, ignored)) {
            reportError(kToolName, o.input, "is a directory");
            return kExitFailure;
        }
        try {
            requireRegularFile(o.input);  // a FIFO would block the open; standard input is "-"
        } catch (const dsm::Error& e) {
            reportException(kToolName, e, o.input);
            return kExitFailure;
        }
        inputFile.open(o.input, std::ios::binary);
        if (!inputFile) {
            const std::string reason = std::error_code(errno, std::generic_category()).message();
            reportError(kToolName, o.input, "cannot open: " + reason);
            return kExitFailure;
        }
        inputName = o.input;
    }

    std::unique_ptr<QueryMode> mode;
    SoftShadowQuery* soft = nullptr;
    std::shared_ptr<const dsm::SoftShadowTracer> tracer;
    Details details = Details::None;
    if (o.areaLight.empty()) {
        dsm::LookupOptions lookup;
        lookup.filter = *dsm::pixelFilterFromName(o.filter);  // CLI11 checked the name
        lookup.filterWidth = o.filterWidth;
        lookup.level = level;
        lookup.bias = o.biasValue;
        mode = std::make_unique<PointLookup>(system, handle, spaceFromName(o.space), lookup);
    } else {
        const dsm::AreaLightSize size = parseAreaLight(o.areaLight);
        try {
            const dsm::AreaLight light = dsm::AreaLight::forMap(map->info(), size);
            tracer = std::make_shared<const dsm::SoftShadowTracer>(map, light);
        } catch (const std::exception& e) {
            reportException(kToolName, e, mapName, displayNames);
            return kExitFailure;
        }
        dsm::SoftShadowOptions shadow;
        shadow.samples = o.lightSamples;
        if (o.layers != 0) shadow.layers = o.layers;
        shadow.zThreshold = o.zThreshold;
        shadow.bias = o.biasValue;
        shadow.seed = o.seed;
        const SoftMethod method = o.soft == "pcf" ? SoftMethod::Pcf : SoftMethod::Mtsm;
        details = method == SoftMethod::Pcf ? Details::Pcf : Details::Traced;
        auto query = std::make_unique<SoftShadowQuery>(tracer, spaceFromName(o.space), method, shadow);
        soft = query.get();
        mode = std::move(query);
    }
    AnswerWriter writer(o.format == "json" ? Format::Json : Format::Csv, map->info().channels, o.errorBound,
                        details, /*errorColumn=*/o.errors == "inline");
    Session session(o, map->path(), *mode, writer);

    const auto start = std::chrono::steady_clock::now();
    Stop stop = Stop::None;
    if (o.header) writer.header();
    try {
        stop = session.points(points);
        if (stop == Stop::None && (queriesFromStdin || inputFile.is_open()))
            stop = session.lines(queriesFromStdin ? *std::cin.rdbuf() : *inputFile.rdbuf(), inputName);
    } catch (const std::exception& e) {
        writer.flush();
        reportException(kToolName, e, mapName, displayNames);
        stop = Stop::MapError;
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (inputFile.is_open() && inputFile.bad()) {
        reportError(kToolName, inputName, "read error");
        stop = Stop::InputError;
    }
    if (stop == Stop::OutputError) std::cerr << kToolName << ": ERROR: cannot write to standard output\n";
    if (o.stats && o.format == "json") {
        printStatsJson(session.totals, seconds, map->cache().stats(), soft ? &soft->stats() : nullptr,
                       tracer ? tracer->hierarchyTilesBuilt() : 0);
    } else if (o.stats) {
        printStats(session.totals, seconds, map->cache().stats());
        if (soft) printSoftStats(soft->stats(), tracer->hierarchyTilesBuilt());
    }
    return stop == Stop::None && session.totals.bad == 0 ? kExitOk : kExitFailure;
}

}  // namespace

int main(int argc, char** argv) {
    // Unsynchronised streams buffer standard input, which lets the tool see
    // when no further query is waiting (it then flushes its answers).
    std::ios::sync_with_stdio(false);

    Options o;
    CLI::App app{"Look up shadow visibility in a deep shadow map (.dsm) for points read one per line (x y z) "
                 "from standard input, a file, or --point. Prints one answer line per query.",
                 kToolName};
    app.add_option("FILE", o.map, "The deep shadow map (.dsm); - reads it from standard input")
        ->required()
        ->type_name("");
    app.add_option("-i,--input", o.input,
                   "Read queries from this file (- = standard input; the default unless --point is given)");
    app.add_option("-p,--point", o.points, "A query X,Y,Z from the command line (repeatable), answered first")
        ->type_name("X,Y,Z")
        ->allow_extra_args(false);
    app.add_option("-s,--space", o.space, "Space of the query points")
        ->check(CLI::IsMember({"world", "light", "raster"}))
        ->capture_default_str();
    app.add_option("-w,--filter-width", o.filterWidth, "Filter width in level-0 pixels")
        ->check(finiteNumberIn(0.0, kMaxFilterWidth))
        ->capture_default_str();
    app.add_option("-f,--filter", o.filter, "Lookup filter")
        ->check(CLI::IsMember({"box", "triangle", "gaussian"}))
        ->capture_default_str();
    app.add_option("-l,--level", o.level, "Mip level: auto (from the filter width, blending two levels) or L")
        ->type_name("auto|L")
        ->capture_default_str();
    app.add_option("-b,--bias", o.bias,
                   "Depth bias subtracted from each query depth (light units): auto (from the map: a pixel's "
                   "depth footprint at the query's depth) or a number; with --area-light the receiver bias, "
                   "auto adding --z-threshold, a number >= 0")
        ->type_name("auto|B")
        ->capture_default_str();
    app.add_option("--format", o.format, "Answer format: CSV lines or JSON Lines")
        ->check(CLI::IsMember({"csv", "json"}))
        ->capture_default_str();
    app.add_flag("--header", o.header, "Print a CSV header line first (csv only)");
    app.add_flag("-e,--error-bound", o.errorBound, "Add each answer's compression error bound");
    app.add_flag("--strict", o.strict, "Stop at the first bad line (exit status 1)");
    app.add_option("--errors", o.errors,
                   "Where bad queries are reported: stderr (one line each), inline (in the answer stream: CSV rows "
                   "gain an error column, JSON answers carry \"error\"; nothing on standard error) or quiet "
                   "(only the placeholder answer)")
        ->check(CLI::IsMember({"stderr", "inline", "quiet"}))
        ->capture_default_str();
    app.add_flag("--stats", o.stats,
                 "Print throughput, tile-cache and soft-shadow statistics to standard error at the end (one JSON "
                 "object with --format json)");
    app.add_option("--cache-mb", o.cacheMiB, "Tile cache budget in MiB")
        ->check(finiteNumberIn(0.0, kMaxCacheMiB))
        ->type_name("MIB")
        ->capture_default_str();
    app.add_option("--area-light", o.areaLight,
                   "Soft shadows of an area light centred on the map's light: a disk of radius R or a rectangle "
                   "W wide and H high (light-space units); world or light points only")
        ->type_name("disk:R|rect:W,H");
    app.add_option("--light-samples", o.lightSamples, "Light samples (rays) per soft query")
        ->check(CLI::Range(1, kMaxLightSamples))
        ->type_name("N")
        ->capture_default_str();
    app.add_option("--layers", o.layers, "Map layers a soft query uses (0 = all)")
        ->check(integerIn(0, 255))
        ->type_name("K")
        ->capture_default_str();
    app.add_option("--z-threshold", o.zThreshold, "Depth tolerance of a ray hitting a stored sample (light units)")
        ->check(finiteNumberIn(0.0, kMaxLength))
        ->type_name("Z")
        ->capture_default_str();
    app.add_option("--seed", o.seed, "Seed of the light samples (a non-negative integer)")
        ->check(integerIn(0, UINT64_MAX))
        ->capture_default_str();
    app.add_option("--soft", o.soft, "Soft-shadow method: mtsm (ray tracing the map) or pcf (the PCF baseline)")
        ->check(CLI::IsMember({"mtsm", "pcf"}))
        ->capture_default_str();
    configureApp(app, kToolName, kDocumentation);
    app.footer("Exit status: 0 when every query was answered, 1 when a line was bad or the map could not be "
               "read, 2 on a usage error.\nDocumentation: " +
               std::string(kDocumentation));

    if (const int status = parseArguments(app, argc, argv); status >= 0) return status;

    std::optional<unsigned> level;
    std::vector<std::array<double, 3>> points;
    try {
        o.biasValue = biasFromText(o.bias);
        if (o.header && o.format != "csv") throw UsageError("--header applies to --format csv only");
        level = levelFromText(o.level);
        for (const std::string& p : o.points) points.push_back(parsePointArgument(p));
        checkSoftOptions(app, o);
    } catch (const UsageError& e) {
        std::cerr << kToolName << ": " << e.what() << "\nRun with --help for more information.\n";
        return kExitUsage;
    }

    try {
        return run(o, points, level);
    } catch (const UsageError& e) {
        std::cerr << kToolName << ": " << e.what() << "\nRun with --help for more information.\n";
        return kExitUsage;
    } catch (const std::exception& e) {
        std::cout.flush();
        std::cerr << oneLine(std::string(kToolName) + ": ERROR: " + exceptionMessage(e)) << '\n';
        return kExitFailure;
    }
}
