// dsm-lookup's query lines (docs/dsm-lookup.md, Input): reading lines of
// bounded length from a stream and parsing "x y z" from each. The line format
// is the tool's, not libdsm's; it lives here so that the fuzzer
// (fuzz/fuzz_query_line.cpp) and the tests call the tool's own code.
#pragma once

#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <optional>
#include <streambuf>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace dsm::tools {

/// Longer lines are reported as bad rather than held in memory whole.
constexpr std::size_t kMaxLineBytes = 4096;

/// Makes a piece of input safe to quote in a one-line message.
inline std::string quotedInput(std::string_view text) {
    constexpr std::size_t kMaxShown = 32;
    std::string out = "'";
    for (std::size_t i = 0; i < text.size() && i < kMaxShown; ++i) {
        const auto c = static_cast<unsigned char>(text[i]);
        out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
    }
    if (text.size() > kMaxShown) out += "...";
    return out + "'";
}

/// A finite decimal number filling all of `text` (one leading sign, '+' or
/// '-'), or nothing.
inline std::optional<double> parseNumber(std::string_view text) {
    // from_chars takes '-' but not '+': strip a '+', and with it the chance
    // of a second sign ("+-1").
    if (!text.empty() && text.front() == '+') {
        text.remove_prefix(1);
        if (!text.empty() && text.front() == '-') return std::nullopt;
    }
    double value = 0.0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (error != std::errc() || end != text.data() + text.size() || !std::isfinite(value)) return std::nullopt;
    return value;
}

/// What one input line holds: nothing to answer (blank or comment), a point,
/// or a complaint about it.
struct ParsedLine {
    enum class Kind { Skip, Point, Bad } kind = Kind::Skip;
    std::array<double, 3> point{};
    std::string problem;
};

/// The fields of a line: separated by spaces, tabs (and a stray '\r') or by
/// one comma with optional blanks around it. Two commas in a row, or a comma
/// at either end, enclose an empty field (so "1,,2,3" has four fields).
inline std::vector<std::string_view> splitQueryFields(std::string_view line) {
    const auto isBlank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
    std::vector<std::string_view> fields;
    bool afterComma = false;  // a comma since the last field: the next field may be empty
    std::size_t i = 0;
    for (;;) {
        while (i < line.size() && isBlank(line[i])) ++i;
        if (i == line.size()) {
            if (afterComma) fields.emplace_back();
            return fields;
        }
        if (line[i] == ',') {
            if (afterComma || fields.empty()) fields.emplace_back();
            afterComma = true;
            ++i;
            continue;
        }
        const std::size_t start = i;
        while (i < line.size() && !isBlank(line[i]) && line[i] != ',') ++i;
        fields.push_back(line.substr(start, i - start));
        afterComma = false;
    }
}

/// "x y z": three finite numbers (splitQueryFields); '#' starts a comment that
/// runs to the end of the line.
inline ParsedLine parseQueryLine(std::string_view line) {
    ParsedLine result;
    if (const auto hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    const std::vector<std::string_view> fields = splitQueryFields(line);
    if (fields.empty()) return result;
    result.kind = ParsedLine::Kind::Bad;
    if (fields.size() != 3) {
        result.problem = "expected 3 numbers (x y z), found " + std::to_string(fields.size()) + " fields";
        return result;
    }
    for (std::size_t k = 0; k < 3; ++k) {
        const std::optional<double> value = parseNumber(fields[k]);
        if (!value) {
            result.problem = std::string("xyz").substr(k, 1) + " " + quotedInput(fields[k]) + " is not a finite number";
            return result;
        }
        result.point[k] = *value;
    }
    result.kind = ParsedLine::Kind::Point;
    return result;
}

/// Reads lines of at most kMaxLineBytes; longer ones are consumed to their end
/// and flagged. Reads the stream buffer directly: a line is answered as soon as
/// its newline arrives, whatever follows.
class LineReader {
public:
    explicit LineReader(std::streambuf& in) : in_(in) {}

    /// False at the end of the input. `tooLong` is set for an overlong line,
    /// of which `line` holds the start.
    bool next(std::string& line, bool& tooLong) {
        line.clear();
        tooLong = false;
        bool any = false;
        for (;;) {
            const int c = in_.sbumpc();
            if (c == std::char_traits<char>::eof()) return any;
            any = true;
            if (c == '\n') return true;
            if (line.size() < kMaxLineBytes) line.push_back(static_cast<char>(c));
            else tooLong = true;
        }
    }

    /// True when the next character can be read without waiting: the caller
    /// flushes its answers before a read that may block.
    bool inputWaiting() { return in_.in_avail() > 0; }

private:
    std::streambuf& in_;
};

}  // namespace dsm::tools
