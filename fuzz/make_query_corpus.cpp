// Writes the seed corpus of fuzz_query_line: dsm-lookup query streams
// (docs/dsm-lookup.md, Input) as a batch file or a coprocess would send them:
// world, light and raster points, separated by spaces, tabs or commas, with
// comments, blank lines, CRLF endings, a last line without a newline, bad
// lines of every kind and a line over the length bound.
//
//   fuzz_make_query_corpus DIR     creates DIR if needed and writes DIR/seed-*.txt
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "query_line.h"

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
        return 2;
    }
    const std::filesystem::path dir = argv[1];
    const std::vector<std::pair<std::string, std::string>> seeds = {
        {"world", "0.1 -0.2 1.5\n0 0 0.5\n-1.25e-1 +2 3E2\n"},
        {"light", "# light space: x right, y up, z depth\n0 0 2.5\n-0.75\t0.5\t4\n\n1e-3 -1e-3 1e3\n"},
        {"raster", "0.5 0.5 0\n12.5,3.5,2\n511.999 0 1.0e1 # last pixel\n"},
        {"commas", "1,2,3\n1, 2, 3\n1 ,2 ,3\n\t1 ,\t2,  3\n"},
        {"crlf", "1.5 2.5 3\r\n# comment\r\n\r\n2.5,1.5,3\r\n"},
        {"no-final-newline", "0.25 0.5 0.75\n1 1 1"},
        {"bad", "1 2\nx 2 3\n1 2 3 4\nnan 1 2\n1 inf 2\n1 1e999 1\n1,,2,3\n,1,2\n+-1 2 3\n1 2 3x\n\x01\xff 2 3\n"},
        {"long", std::string(dsm::tools::kMaxLineBytes + 8, '1') + " 1 1\n1 2 3\n"},
        {"streaming", "0 0 1\n0 0 1\n0 0 1\n# keep-alive\n0.5 0.5 0.5\n"},
    };
    try {
        std::filesystem::create_directories(dir);
        for (const auto& [name, text] : seeds) {
            const std::filesystem::path path = dir / ("seed-" + name + ".txt");
            std::ofstream out(path, std::ios::binary);
            out << text;
            if (!out) throw std::runtime_error("cannot write " + path.string());
            std::printf("fuzz_make_query_corpus: %s (%zu bytes)\n", path.string().c_str(), text.size());
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_make_query_corpus: %s\n", e.what());
        return 1;
    }
    return 0;
}
