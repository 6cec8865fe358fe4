// write_png / read_png on their own (daemon/render/png_writer): the file
// write_png makes is checked byte by byte (signature, chunk CRCs, IHDR),
// read_png is checked against PNG files built here by hand (no libpng), and
// both name the file and the reason when they fail. render_test.cpp covers
// a rendered frame's round trip through both.
#include "render/png_writer.hpp"

#include <gtest/gtest.h>

#include <sys/resource.h>

#include <algorithm>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <initializer_list>
#include <string>
#include <utility>
#include <vector>

#include "support/process_support.hpp"

namespace tissue::render {
namespace {

using tissue::testing::slurp;
using tissue::testing::TempDir;
using tissue::testing::write_text;

// Every pixel different, alpha included (0 and 255 among them).
Image pattern(int width, int height) {
  Image img;
  img.width = width;
  img.height = height;
  img.rgba.resize(4 * static_cast<std::size_t>(width) * height);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      std::uint8_t* p = &img.rgba[4 * (static_cast<std::size_t>(y) * width + x)];
      p[0] = static_cast<std::uint8_t>(x * 37 + y * 11);
      p[1] = static_cast<std::uint8_t>(x * 5 + y * 71 + 3);
      p[2] = static_cast<std::uint8_t>((x ^ y) * 13 + 200);
      p[3] = static_cast<std::uint8_t>((x + 2 * y) % 5 == 0 ? 0 : (x + y) % 5 == 1 ? 255 : 17 * (x + y));
    }
  }
  return img;
}

// ------------------------------------------------ PNG bytes, by hand

std::uint32_t crc32(const std::string& bytes) {
  std::uint32_t c = 0xffffffffu;
  for (const char ch : bytes) {
    c ^= static_cast<std::uint8_t>(ch);
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}

std::uint32_t be32(const std::string& s, std::size_t at) {
  return (static_cast<std::uint32_t>(static_cast<std::uint8_t>(s[at])) << 24) |
         (static_cast<std::uint32_t>(static_cast<std::uint8_t>(s[at + 1])) << 16) |
         (static_cast<std::uint32_t>(static_cast<std::uint8_t>(s[at + 2])) << 8) |
         static_cast<std::uint32_t>(static_cast<std::uint8_t>(s[at + 3]));
}

std::string put_be32(std::uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8), static_cast<char>(v)};
}

const std::string kSignature("\x89PNG\r\n\x1a\n", 8);

struct Chunk {
  std::string type, data;
  bool crc_ok = false;
};

// The chunks after the signature; fails the test on a malformed layout.
std::vector<Chunk> chunks_of(const std::string& file) {
  std::vector<Chunk> out;
  EXPECT_EQ(file.substr(0, 8), kSignature);
  std::size_t at = 8;
  while (at + 12 <= file.size()) {
    const std::uint32_t length = be32(file, at);
    if (at + 12 + length > file.size()) break;
    Chunk c;
    c.type = file.substr(at + 4, 4);
    c.data = file.substr(at + 8, length);
    c.crc_ok = be32(file, at + 8 + length) == crc32(c.type + c.data);
    out.push_back(c);
    at += 12 + length;
  }
  EXPECT_EQ(at, file.size()) << "trailing bytes after the last whole chunk";
  return out;
}

std::string chunk(const std::string& type, const std::string& data) {
  return put_be32(static_cast<std::uint32_t>(data.size())) + type + data + put_be32(crc32(type + data));
}

// A zlib stream of stored (uncompressed) deflate blocks.
std::string zlib_stored(const std::string& raw) {
  std::string out("\x78\x01", 2);
  std::size_t at = 0;
  do {
    const std::size_t n = std::min<std::size_t>(raw.size() - at, 65535);
    const bool last = at + n == raw.size();
    out += static_cast<char>(last ? 1 : 0);
    out += static_cast<char>(n & 0xff);
    out += static_cast<char>(n >> 8);
    out += static_cast<char>(~n & 0xff);
    out += static_cast<char>((~n >> 8) & 0xff);
    out += raw.substr(at, n);
    at += n;
  } while (at < raw.size());
  std::uint32_t a = 1, b = 0;
  for (const char ch : raw) {
    a = (a + static_cast<std::uint8_t>(ch)) % 65521;
    b = (b + a) % 65521;
  }
  return out + put_be32((b << 16) | a);
}

// A PNG of `rows` (filter type 0 each) in the given colour type, 8 bits.
std::string hand_made_png(int width, int height, int colour_type, const std::vector<std::string>& rows,
                          const std::string& extra_chunks = "") {
  std::string ihdr = put_be32(width) + put_be32(height);
  ihdr += {8, static_cast<char>(colour_type), 0, 0, 0};
  std::string raw;
  for (const std::string& r : rows) raw += '\0' + r;
  return kSignature + chunk("IHDR", ihdr) + extra_chunks + chunk("IDAT", zlib_stored(raw)) + chunk("IEND", "");
}

std::vector<std::uint8_t> bytes(std::initializer_list<int> v) { return {v.begin(), v.end()}; }

// ------------------------------------------------------------- writing

// Odd sizes (a single pixel, one row, one column, widths that are not a
// multiple of anything) come back pixel for pixel, alpha included.
TEST(PngWriter, OddSizesRoundTripPixelForPixel) {
  TempDir dir;
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {1, 7}, {7, 1}, {3, 5}, {13, 11}, {257, 2}}) {
    const Image img = pattern(w, h);
    const std::string path = dir / (std::to_string(w) + "x" + std::to_string(h) + ".png");
    write_png(img, path);
    const Image back = read_png(path);
    EXPECT_EQ(back.width, w);
    EXPECT_EQ(back.height, h);
    EXPECT_EQ(back.rgba, img.rgba) << w << "x" << h;
  }
  // Row 0 is the top row: a picture and its upside-down copy differ.
  Image top(pattern(2, 2)), flipped(top);
  std::copy(top.rgba.begin(), top.rgba.begin() + 8, flipped.rgba.begin() + 8);
  std::copy(top.rgba.begin() + 8, top.rgba.end(), flipped.rgba.begin());
  write_png(flipped, dir / "f.png");
  EXPECT_EQ(read_png(dir / "f.png").rgba, flipped.rgba);
}

// The file itself, read without libpng: signature, IHDR first with the
// image's size as 8-bit RGBA (colour type 6), no interlace, IDAT, IEND last,
// and every chunk's CRC right.
TEST(PngWriter, FileIsAnRgba8PngWithTheImagesSizeAndGoodCrcs) {
  TempDir dir;
  for (const auto& [w, h] : std::vector<std::pair<int, int>>{{1, 1}, {5, 3}, {300, 17}}) {
    const std::string path = dir / "x.png";
    write_png(pattern(w, h), path);
    const std::string file = slurp(path);
    ASSERT_GT(file.size(), 8u + 25u + 12u);
    const std::vector<Chunk> chunks = chunks_of(file);
    ASSERT_GE(chunks.size(), 3u);
    EXPECT_EQ(chunks.front().type, "IHDR");
    ASSERT_EQ(chunks.front().data.size(), 13u);
    const std::string& ihdr = chunks.front().data;
    EXPECT_EQ(be32(ihdr, 0), static_cast<std::uint32_t>(w));
    EXPECT_EQ(be32(ihdr, 4), static_cast<std::uint32_t>(h));
    EXPECT_EQ(static_cast<int>(ihdr[8]), 8) << "bit depth";
    EXPECT_EQ(static_cast<int>(ihdr[9]), 6) << "colour type RGBA";
    EXPECT_EQ(static_cast<int>(ihdr[10]), 0) << "compression";
    EXPECT_EQ(static_cast<int>(ihdr[11]), 0) << "filter";
    EXPECT_EQ(static_cast<int>(ihdr[12]), 0) << "interlace";
    EXPECT_EQ(chunks.back().type, "IEND");
    EXPECT_TRUE(chunks.back().data.empty());
    int idat = 0;
    for (const Chunk& c : chunks) {
      EXPECT_TRUE(c.crc_ok) << c.type;
      idat += c.type == "IDAT" ? 1 : 0;
    }
    EXPECT_GE(idat, 1);
  }
}

TEST(PngWriter, OverwritesAnExistingFileCompletely) {
  TempDir dir;
  const std::string path = dir / "x.png";
  write_text(path, std::string(1 << 20, 'z'));  // longer than any PNG below
  write_png(pattern(4, 4), path);
  const std::string file = slurp(path);
  EXPECT_LT(file.size(), 4096u);
  EXPECT_EQ(chunks_of(file).back().type, "IEND");
  EXPECT_EQ(read_png(path).rgba, pattern(4, 4).rgba);
}

// Writes `img` to `path` and returns the error's text ("" and a test
// failure when there is none).
std::string write_error(const Image& img, const std::string& path) {
  try {
    write_png(img, path);
  } catch (const RenderError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no error writing " << path;
  return {};
}

Image noise(int width, int height) {
  Image img = pattern(width, height);
  std::uint32_t s = 12345;
  for (auto& b : img.rgba) b = static_cast<std::uint8_t>((s = s * 1103515245u + 12345u) >> 16);
  return img;
}

TEST(PngWriter, WriteErrorsNameTheFileAndTheReason) {
  TempDir dir;
  const std::string missing = dir / "no/such/dir/x.png";
  // The messages of util::PendingOutputFile, the one writer of output files.
  EXPECT_EQ(write_error(pattern(2, 2), missing), "cannot write " + missing + ": cannot create a temporary file in '" +
                                                     dir.path() + "/no/such/dir': No such file or directory");
  EXPECT_EQ(write_error(pattern(2, 2), dir.path()), "cannot write " + dir.path() + ": is a directory");
  // A full disk: a small picture fails when the buffered bytes are flushed,
  // a large one inside libpng, whose message comes with the system's.
  EXPECT_EQ(write_error(pattern(1, 1), "/dev/full"), "cannot write /dev/full: No space left on device");
  EXPECT_EQ(write_error(noise(512, 512), "/dev/full"), "cannot write /dev/full: No space left on device");
}

// An image whose size and pixels disagree is refused before the file is
// touched (libpng would read past the pixels, or refuse an empty side with
// a message only on stderr).
TEST(PngWriter, AnInconsistentImageIsRefusedBeforeTheFileIsTouched) {
  TempDir dir;
  const std::string path = dir / "kept.png";
  write_text(path, "an older picture");
  Image empty;
  empty.height = 3;
  EXPECT_EQ(write_error(empty, path),
            "cannot write " + path + ": the image is 0 x 3 pixels (each side must be 1 to 1000000)");
  Image wide = pattern(1, 1);
  wide.width = 1000001;
  EXPECT_EQ(write_error(wide, path),
            "cannot write " + path + ": the image is 1000001 x 1 pixels (each side must be 1 to 1000000)");
  Image short_of_pixels = pattern(4, 3);
  short_of_pixels.rgba.resize(4 * 4 * 3 - 1);
  EXPECT_EQ(write_error(short_of_pixels, path),
            "cannot write " + path + ": the image has 47 bytes of pixels, 4 x 3 RGBA needs 48");
  Image too_many = pattern(4, 3);
  too_many.rgba.push_back(0);
  EXPECT_EQ(write_error(too_many, path),
            "cannot write " + path + ": the image has 49 bytes of pixels, 4 x 3 RGBA needs 48");
  EXPECT_EQ(slurp(path), "an older picture");
}

// A write that fails part-way (here the file-size limit, as a full disk
// would) leaves no truncated picture behind, and an older picture at the
// path stays as it was (it was truncated, then removed). In a child
// process: the limit and its signal must not reach the rest of the suite.
// Runs in the child: exit 0 when the write failed with the file and the
// reason named and the path holds what it held before.
[[noreturn]] void write_beyond_the_file_size_limit(const std::string& path) {
  std::signal(SIGXFSZ, SIG_IGN);
  rlimit limit{};
  limit.rlim_cur = limit.rlim_max = 4096;
  if (setrlimit(RLIMIT_FSIZE, &limit) != 0) std::_Exit(2);
  const bool existed = std::filesystem::exists(path);
  const std::string before = existed ? slurp(path) : std::string();
  const std::string error = write_error(noise(256, 256), path);
  const bool named =
      error.rfind("cannot write " + path + ": ", 0) == 0 && error.find("File too large") != std::string::npos;
  const bool as_before =
      existed ? std::filesystem::exists(path) && slurp(path) == before : !std::filesystem::exists(path);
  const bool no_temporary =
      std::distance(std::filesystem::directory_iterator(std::filesystem::path(path).parent_path()),
                    std::filesystem::directory_iterator()) == (existed ? 1 : 0);
  std::_Exit(named && as_before && no_temporary ? 0 : 1);
}

TEST(PngWriter, AWriteThatFailsPartWayLeavesThePathAsItWas) {
  TempDir dir;
  const std::string path = dir / "cut.png";
  EXPECT_EXIT(write_beyond_the_file_size_limit(path), ::testing::ExitedWithCode(0), "");
  write_text(path, "an older picture");
  EXPECT_EXIT(write_beyond_the_file_size_limit(path), ::testing::ExitedWithCode(0), "");
  EXPECT_EQ(slurp(path), "an older picture");
}

// ------------------------------------------------------------- reading

TEST(PngWriter, ReadPngTurnsGreyRgbAndPaletteFilesIntoRgba) {
  TempDir dir;
  // Grey (colour type 0), 3 x 2: each grey level copied to r, g, b; opaque.
  write_text(dir / "grey.png", hand_made_png(3, 2, 0, {std::string("\x00\x80\xff", 3), "\x10\x20\x30"}));
  const Image grey = read_png(dir / "grey.png");
  EXPECT_EQ(grey.width, 3);
  EXPECT_EQ(grey.height, 2);
  EXPECT_EQ(grey.rgba, bytes({0,  0,  0,  255, 128, 128, 128, 255, 255, 255, 255, 255,  //
                              16, 16, 16, 255, 32,  32,  32,  255, 48,  48,  48,  255}));
  // RGB (colour type 2), 2 x 1: opaque.
  write_text(dir / "rgb.png", hand_made_png(2, 1, 2, {"\x01\x02\x03\xfa\xfb\xfc"}));
  const Image rgb = read_png(dir / "rgb.png");
  EXPECT_EQ(rgb.width, 2);
  EXPECT_EQ(rgb.height, 1);
  EXPECT_EQ(rgb.rgba, bytes({1, 2, 3, 255, 250, 251, 252, 255}));
  // RGBA (colour type 6), 1 x 3: row order and alpha kept.
  write_text(dir / "rgba.png", hand_made_png(1, 3, 6, {"\x0a\x0b\x0c\x0d", "\x1a\x1b\x1c\xff", "\x2a\x2b\x2c\x01"}));
  const Image rgba = read_png(dir / "rgba.png");
  EXPECT_EQ(rgba.width, 1);
  EXPECT_EQ(rgba.height, 3);
  EXPECT_EQ(rgba.rgba, bytes({10, 11, 12, 13, 26, 27, 28, 255, 42, 43, 44, 1}));
  // Palette (colour type 3) with a tRNS alpha for entry 1.
  const std::string palette =
      chunk("PLTE", std::string("\xff\x00\x00\x00\x00\xff", 6)) + chunk("tRNS", std::string("\xff\x40", 2));
  write_text(dir / "pal.png", hand_made_png(2, 1, 3, {std::string("\x01\x00", 2)}, palette));
  const Image pal = read_png(dir / "pal.png");
  EXPECT_EQ(pal.rgba, bytes({0, 0, 255, 64, 255, 0, 0, 255}));
}

TEST(PngWriter, ReadErrorsNameTheFileAndLibpngsReason) {
  TempDir dir;
  const auto message = [](const std::string& path) -> std::string {
    try {
      const Image img = read_png(path);
      ADD_FAILURE() << "read " << path << " as " << img.width << "x" << img.height;
    } catch (const RenderError& e) {
      return e.what();
    }
    return {};
  };
  const std::string missing = dir / "missing.png";
  EXPECT_EQ(message(missing), "cannot read " + missing + ": No such file or directory");
  write_text(dir / "text.png", "just some text, long enough to hold a PNG signature");
  EXPECT_EQ(message(dir / "text.png"), "cannot read " + dir / "text.png" + ": Not a PNG file");

  const std::string good = hand_made_png(2, 2, 2, {"\x01\x02\x03\x04\x05\x06", "\x07\x08\x09\x0a\x0b\x0c"});
  write_text(dir / "good.png", good);
  EXPECT_EQ(read_png(dir / "good.png").rgba, bytes({1, 2, 3, 255, 4, 5, 6, 255, 7, 8, 9, 255, 10, 11, 12, 255}));
  // A header that reads but pixels that do not: the second stage fails too.
  const std::size_t idat = good.find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  write_text(dir / "cut.png", good.substr(0, idat + 8));
  std::string what = message(dir / "cut.png");
  EXPECT_EQ(what.rfind("cannot read " + dir / "cut.png" + ": ", 0), 0u) << what;
  EXPECT_GT(what.size(), ("cannot read " + dir / "cut.png" + ": ").size()) << "no reason given";
  // A corrupted IHDR (bad CRC) is refused before any pixel is read.
  std::string bad_crc = good;
  bad_crc[8 + 8 + 3] ^= 0x01;  // a byte of the width
  write_text(dir / "crc.png", bad_crc);
  what = message(dir / "crc.png");
  EXPECT_EQ(what.rfind("cannot read " + dir / "crc.png" + ": ", 0), 0u) << what;
  EXPECT_NE(what.find("CRC"), std::string::npos) << what;
}

}  // namespace
}  // namespace tissue::render
