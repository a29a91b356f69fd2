// Writes the seed corpus of fuzz_validate: the small valid maps of
// seed_maps.h.
//
//   fuzz_make_corpus DIR     creates DIR if needed and writes DIR/seed-*.dsm
#include <cstdio>
#include <exception>
#include <filesystem>

#include "seed_maps.h"

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
        return 2;
    }
    try {
        std::filesystem::create_directories(argv[1]);
        seed_maps::writeSeedMaps(argv[1]);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_make_corpus: %s\n", e.what());
        return 1;
    }
    return 0;
}
