#include "evio/sensors/line_reader.h"

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

TEST(LineReader, LinesAcrossChunkBoundariesAndLineEndings) {
  evio_test::TempDir dir;
  std::string text;
  std::vector<std::string> expected;
  for (int i = 0; i < 500; ++i) {
    std::string line(static_cast<size_t>(i % 37), static_cast<char>('a' + i % 26));
    line += std::to_string(i);
    expected.push_back(line);
    text += line + (i % 3 == 0 ? "\r\n" : "\n");
  }
  text += "last-without-newline";
  expected.push_back("last-without-newline");
  const std::string path = dir.write("lines.txt", text);
  LineReader reader(path, 64, 48);  // tiny chunks: most lines straddle a refill
  std::string_view line;
  size_t n = 0;
  while (reader.next(&line)) {
    ASSERT_LT(n, expected.size());
    ASSERT_EQ(line, expected[n]) << "line " << n + 1;
    ++n;
    EXPECT_EQ(reader.line_number(), static_cast<int64_t>(n));
  }
  EXPECT_EQ(n, expected.size());
  EXPECT_EQ(reader.bytes_consumed(), reader.file_size());
}

TEST(LineReader, OverlongLineNamesTheLine) {
  evio_test::TempDir dir;
  const std::string path = dir.write("bin.txt", "ok\n" + std::string(200, 'x') + "\n");
  LineReader reader(path, 64, 100);
  std::string_view line;
  ASSERT_TRUE(reader.next(&line));
  try {
    reader.next(&line);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bin.txt:2: line longer than 100 bytes"), std::string::npos) << e.what();
  }
}

TEST(LineReader, MissingFileAndDirectory) {
  evio_test::TempDir dir;
  EXPECT_THROW(LineReader(dir.file("nope.txt")), InputError);
  EXPECT_THROW(LineReader(dir.path()), InputError);
  LineReader empty(dir.write("empty.txt", ""));
  std::string_view line;
  EXPECT_FALSE(empty.next(&line));
}

}  // namespace
}  // namespace evio
