// Streaming decoders of LZ4 frames (lz4 frame format, magic 04 22 4d 18) and Zstd frames (magic
// 28 b5 2f fd) into a growable buffer with a size limit, for readers whose blocks are compressed
// (AEDAT 4.0 packets). The output grows as data is actually produced, so a bogus size costs no
// memory up front; one or more concatenated frames are decoded. Errors are evio::InputErrors
// naming the file, the block (`where`) and the compressed byte they stopped at.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

struct LZ4F_dctx_s;
struct ZSTD_DCtx_s;

namespace evio::detail {

struct DecompressLimit {
  size_t max_bytes;       // largest decompressed block accepted
  std::string expected;   // the expected form when it is exceeded, e.g. "packets of at most 256 MiB ..."
};

class Lz4FrameDecoder {
 public:
  Lz4FrameDecoder();
  ~Lz4FrameDecoder();
  Lz4FrameDecoder(const Lz4FrameDecoder&) = delete;
  Lz4FrameDecoder& operator=(const Lz4FrameDecoder&) = delete;

  // Decodes src[0, n) into *out (resized to the decoded size). `expected`: the form of src.
  void decode(const uint8_t* src, size_t n, std::vector<uint8_t>* out, const DecompressLimit& limit,
              const std::string& path, const std::string& where, const char* expected);

 private:
  LZ4F_dctx_s* ctx_ = nullptr;
};

class ZstdFrameDecoder {
 public:
  ZstdFrameDecoder();
  ~ZstdFrameDecoder();
  ZstdFrameDecoder(const ZstdFrameDecoder&) = delete;
  ZstdFrameDecoder& operator=(const ZstdFrameDecoder&) = delete;

  void decode(const uint8_t* src, size_t n, std::vector<uint8_t>* out, const DecompressLimit& limit,
              const std::string& path, const std::string& where, const char* expected);

 private:
  ZSTD_DCtx_s* ctx_ = nullptr;
};

}  // namespace evio::detail
