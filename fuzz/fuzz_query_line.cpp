// libFuzzer target: the input bytes as dsm-lookup's query stream, read line by
// line with the tool's own LineReader and parseQueryLine()
// (tools/common/query_line.h). Every line must come back as skipped, a point
// of three finite numbers, or a one-line problem of bounded length; a line the
// reader cuts must be no longer than kMaxLineBytes. A crash, a sanitizer
// report, a leak or any of these checks failing is a finding. Built by
// fuzz/CMakeLists.txt.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>

#include "query_line.h"

namespace {

using dsm::tools::LineReader;
using dsm::tools::ParsedLine;

// A problem quotes at most 32 characters of input (quotedInput) besides its
// fixed text: anything much longer means the input leaked into it whole.
constexpr std::size_t kMaxProblemBytes = 128;

void check(const ParsedLine& parsed, const std::string& line) {
    switch (parsed.kind) {
        case ParsedLine::Kind::Skip: break;
        case ParsedLine::Kind::Point:
            for (const double v : parsed.point)
                if (!std::isfinite(v)) std::abort();
            // A point is answered: a line holding '#' before its numbers is a comment.
            if (line.find_first_not_of(" \t\r") != std::string::npos && line[line.find_first_not_of(" \t\r")] == '#')
                std::abort();
            // The point printed back in full precision reads as the same point.
            {
                char text[96];
                std::snprintf(text, sizeof text, "%.17g,%.17g %.17g", parsed.point[0], parsed.point[1], parsed.point[2]);
                const ParsedLine again = dsm::tools::parseQueryLine(text);
                if (again.kind != ParsedLine::Kind::Point || again.point != parsed.point) std::abort();
            }
            break;
        case ParsedLine::Kind::Bad:
            if (parsed.problem.empty() || parsed.problem.size() > kMaxProblemBytes) std::abort();
            for (const char c : parsed.problem)
                if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) std::abort();
            break;
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::stringbuf in(std::string(reinterpret_cast<const char*>(data), size), std::ios::in);
    LineReader reader(in);
    std::string line;
    bool tooLong = false;
    std::size_t consumed = 0;
    while (reader.next(line, tooLong)) {
        if (line.size() > dsm::tools::kMaxLineBytes || (tooLong && line.size() != dsm::tools::kMaxLineBytes))
            std::abort();
        consumed += line.size();
        if (consumed > size) std::abort();  // the reader made up bytes
        if (!tooLong) check(dsm::tools::parseQueryLine(line), line);
    }
    return 0;
}
