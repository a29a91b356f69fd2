// Which part of a multi-part deep EXR is imported (spec/exr-interop.md "Parts and views").
#include "part_selection.h"

#include <algorithm>
#include <cctype>

#include <ImfHeader.h>
#include <ImfPartType.h>
#include <ImfStandardAttributes.h>

#include "dsm/error.h"
#include "exr_common.h"

DSM_NAMESPACE_BEGIN
namespace exr {

using detail::concat;

namespace {

bool isDeep(const Imf::Header& h) { return h.hasType() && Imf::isDeepData(h.type()); }

std::string viewOf(const Imf::Header& h) { return h.hasView() ? h.view() : std::string(); }
std::string nameOf(const Imf::Header& h) { return h.hasName() ? h.name() : std::string(); }

/// Every part, described, with its kind: for errors that list what exists.
std::string listParts(const Imf::MultiPartInputFile& file) {
    std::string out;
    for (int i = 0; i < file.parts(); ++i)
        out += concat(i ? ", " : "", describePart(file, i), isDeep(file.header(i)) ? " deep" : " flat");
    return out;
}

bool allDigits(const std::string& text) {
    return !text.empty() && text.size() <= 9 &&
           std::all_of(text.begin(), text.end(), [](unsigned char c) { return std::isdigit(c); });
}

}  // namespace

std::string describePart(const Imf::MultiPartInputFile& file, int index) {
    const Imf::Header& h = file.header(index);
    std::string out = concat("part ", index);
    if (const std::string name = nameOf(h); !name.empty()) out += concat(" '", safeText(name, detail::kMaxQuotedChars), "'");
    if (const std::string view = viewOf(h); !view.empty())
        out += concat(" (view '", safeText(view, detail::kMaxQuotedChars), "')");
    return out;
}

SelectedPart selectDeepPart(const Imf::MultiPartInputFile& file, const std::string& part, const std::string& view) {
    const int parts = file.parts();
    SelectedPart selected;
    selected.index = -1;
    if (!part.empty()) {
        if (allDigits(part)) {
            const long index = std::stol(part);
            if (index >= parts)
                throw Error(ErrorCode::argument,
                            concat("no part ", index, ": the file has ", parts, parts == 1 ? " part" : " parts", " (",
                                   listParts(file), ")"));
            selected.index = int(index);
        } else {
            for (int i = 0; i < parts && selected.index < 0; ++i)
                if (nameOf(file.header(i)) == part) selected.index = i;
            if (selected.index < 0)
                throw Error(ErrorCode::argument, concat("no part named '", safeText(part, detail::kMaxQuotedChars),
                                                        "' (", listParts(file), ")"));
        }
        if (!isDeep(file.header(selected.index)))
            throw Error(ErrorCode::format, concat(describePart(file, selected.index), " is not a deep image (type '",
                                                  safeText(file.header(selected.index).type()), "')"));
        if (!view.empty() && viewOf(file.header(selected.index)) != view)
            throw Error(ErrorCode::argument, concat(describePart(file, selected.index), " is not of view '",
                                                    safeText(view, detail::kMaxQuotedChars), "'"));
    } else {
        for (int i = 0; i < parts && selected.index < 0; ++i)
            if (isDeep(file.header(i)) && (view.empty() || viewOf(file.header(i)) == view)) selected.index = i;
        if (selected.index < 0) {
            if (!view.empty())
                throw Error(ErrorCode::argument, concat("no deep part of view '", safeText(view, detail::kMaxQuotedChars),
                                                        "' (", listParts(file), ")"));
            if (parts == 1) throw Error(ErrorCode::format, "not a deep image (a flat OpenEXR file)");
            throw Error(ErrorCode::format, concat("no deep part (", listParts(file), ")"));
        }
        // Chosen by default (no view given): name the deep parts not read.
        std::string others;
        for (int i = 0; i < parts && view.empty(); ++i)
            if (i != selected.index && isDeep(file.header(i))) others += concat(others.empty() ? "" : ", ", describePart(file, i));
        if (!others.empty())
            selected.notes.push_back(concat("read ", describePart(file, selected.index),
                                            "; the file has other deep parts: ", others,
                                            " (choose one with --part or --view)"));
    }
    selected.description = describePart(file, selected.index);
    return selected;
}

}  // namespace exr
DSM_NAMESPACE_END
