// dsm-lookup's query-line parser (tools/common/query_line.h): what a line
// holds, the fields it is split into, and the reader's line bounds.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "query_line.h"

namespace {

using dsm::tools::kMaxLineBytes;
using dsm::tools::LineReader;
using dsm::tools::ParsedLine;
using dsm::tools::parseNumber;
using dsm::tools::parseQueryLine;
using dsm::tools::splitQueryFields;

std::vector<std::string> fields(std::string_view line) {
    std::vector<std::string> out;
    for (const std::string_view f : splitQueryFields(line)) out.emplace_back(f);
    return out;
}

void expectPoint(std::string_view line, double x, double y, double z) {
    const ParsedLine parsed = parseQueryLine(line);
    ASSERT_EQ(parsed.kind, ParsedLine::Kind::Point) << "'" << line << "': " << parsed.problem;
    EXPECT_EQ(parsed.point[0], x) << line;
    EXPECT_EQ(parsed.point[1], y) << line;
    EXPECT_EQ(parsed.point[2], z) << line;
}

void expectBad(std::string_view line, const std::string& problem) {
    const ParsedLine parsed = parseQueryLine(line);
    ASSERT_EQ(parsed.kind, ParsedLine::Kind::Bad) << "'" << line << "'";
    EXPECT_EQ(parsed.problem, problem) << "'" << line << "'";
}

TEST(QueryLine, SeparatorsAreBlanksOrOneComma) {
    expectPoint("1.5 2 -3", 1.5, 2.0, -3.0);
    expectPoint("1.5,2,-3", 1.5, 2.0, -3.0);
    expectPoint("\t1.5 ,\t2 , -3 \r", 1.5, 2.0, -3.0);
    expectPoint("1e-3 +2 -0", 1e-3, 2.0, -0.0);
    expectPoint("1 2 3 # a comment, with commas", 1.0, 2.0, 3.0);
}

TEST(QueryLine, BlankAndCommentLinesAreSkipped) {
    for (const char* line : {"", "   ", "\t\r", "# only a comment", "  # 1 2 3"})
        EXPECT_EQ(parseQueryLine(line).kind, ParsedLine::Kind::Skip) << "'" << line << "'";
}

// Two commas in a row enclose an empty field: "1,,2,3" is four fields, not
// the point (1, 2, 3).
TEST(QueryLine, EmptyFieldsBetweenCommasCount) {
    EXPECT_EQ(fields("1,,2,3"), (std::vector<std::string>{"1", "", "2", "3"}));
    EXPECT_EQ(fields(",1,2"), (std::vector<std::string>{"", "1", "2"}));
    EXPECT_EQ(fields("1,2,"), (std::vector<std::string>{"1", "2", ""}));
    EXPECT_EQ(fields("1 , , 2"), (std::vector<std::string>{"1", "", "2"}));
    EXPECT_EQ(fields(","), (std::vector<std::string>{"", ""}));
    expectBad("1,,2,3", "expected 3 numbers (x y z), found 4 fields");
    expectBad("1,,2", "y '' is not a finite number");
    expectBad(",1,2", "x '' is not a finite number");
    expectBad("1,2,", "z '' is not a finite number");
    expectBad("1, 2, 3,", "expected 3 numbers (x y z), found 4 fields");
    expectBad(",", "expected 3 numbers (x y z), found 2 fields");
}

TEST(QueryLine, NumbersMustBeFiniteAndWhole) {
    expectBad("1 2", "expected 3 numbers (x y z), found 2 fields");
    expectBad("1 2 3 4", "expected 3 numbers (x y z), found 4 fields");
    expectBad("x 2 3", "x 'x' is not a finite number");
    expectBad("nan 1 2", "x 'nan' is not a finite number");
    expectBad("1 inf 2", "y 'inf' is not a finite number");
    expectBad("1 1e999 1", "y '1e999' is not a finite number");
    expectBad("1 2 3x", "z '3x' is not a finite number");
    expectBad("1 2 0x10", "z '0x10' is not a finite number");
    // One sign only.
    expectBad("+-1 2 3", "x '+-1' is not a finite number");
    expectBad("1 ++2 3", "y '++2' is not a finite number");
    expectBad("1 2 --3", "z '--3' is not a finite number");
    EXPECT_FALSE(parseNumber("+"));
    EXPECT_FALSE(parseNumber(""));
    EXPECT_EQ(parseNumber("+0.25"), 0.25);
    EXPECT_EQ(parseNumber("-0.25"), -0.25);
}

TEST(QueryLine, ProblemsQuoteTheInputSafely) {
    const std::string field = std::string("\x01\xff") + std::string(40, 'a');
    const ParsedLine parsed = parseQueryLine(field + " 1 2");
    ASSERT_EQ(parsed.kind, ParsedLine::Kind::Bad);
    EXPECT_EQ(parsed.problem, "x '??" + std::string(30, 'a') + "...' is not a finite number");
}

TEST(QueryLine, ReaderBoundsLinesAndKeepsTheLast) {
    const std::string longLine(kMaxLineBytes + 10, '1');
    std::istringstream in("1 2 3\r\n" + longLine + "\n\nlast");
    LineReader reader(*in.rdbuf());
    std::string line;
    bool tooLong = true;
    ASSERT_TRUE(reader.next(line, tooLong));
    EXPECT_EQ(line, "1 2 3\r");
    EXPECT_FALSE(tooLong);
    ASSERT_TRUE(reader.next(line, tooLong));
    EXPECT_TRUE(tooLong);
    EXPECT_EQ(line.size(), kMaxLineBytes);
    ASSERT_TRUE(reader.next(line, tooLong));
    EXPECT_EQ(line, "");
    EXPECT_FALSE(tooLong);
    ASSERT_TRUE(reader.next(line, tooLong));
    EXPECT_EQ(line, "last");
    EXPECT_FALSE(reader.next(line, tooLong));
}

}  // namespace
