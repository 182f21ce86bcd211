#include "frame_decompress.h"

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>

#include "evio/calib/error.h"

namespace evio::detail {
namespace {

std::string num(size_t v) { return std::to_string(v); }

// Doubles the output (at least 64 KiB), up to the limit; throws when the limit is reached.
void grow(std::vector<uint8_t>* out, const DecompressLimit& limit, const std::string& path, const std::string& where,
          const char* what) {
  if (out->size() >= limit.max_bytes) {
    throw InputError(path, 0, where + ": " + what + " data decompresses to more than " + num(limit.max_bytes) + " bytes",
                     limit.expected);
  }
  out->resize(std::min(limit.max_bytes, std::max<size_t>(out->size() * 2, 1 << 16)));
}

}  // namespace

Lz4FrameDecoder::Lz4FrameDecoder() {
  if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx_, LZ4F_VERSION))) ctx_ = nullptr;
}

Lz4FrameDecoder::~Lz4FrameDecoder() {
  if (ctx_ != nullptr) LZ4F_freeDecompressionContext(ctx_);
}

void Lz4FrameDecoder::decode(const uint8_t* src, size_t n, std::vector<uint8_t>* out, const DecompressLimit& limit,
                             const std::string& path, const std::string& where, const char* expected) {
  if (ctx_ == nullptr) throw InputError(path, 0, where + ": cannot create an LZ4 decompression context");
  LZ4F_resetDecompressionContext(ctx_);
  out->resize(std::min(limit.max_bytes, std::max<size_t>(n * 3, 1 << 16)));
  size_t produced = 0, consumed = 0;
  bool in_frame = false;
  while (consumed < n || in_frame) {
    if (produced == out->size()) grow(out, limit, path, where, "LZ4");
    size_t dst = out->size() - produced;
    size_t srcn = n - consumed;
    const size_t r = LZ4F_decompress(ctx_, out->data() + produced, &dst, src + consumed, &srcn, nullptr);
    if (LZ4F_isError(r)) {
      LZ4F_resetDecompressionContext(ctx_);
      throw InputError(path, 0,
                       where + ": corrupt LZ4 data near compressed byte " + num(consumed) + " (" + LZ4F_getErrorName(r) + ")",
                       expected);
    }
    produced += dst;
    consumed += srcn;
    in_frame = r != 0;
    if (in_frame && srcn == 0 && dst == 0 && produced < out->size()) {  // no progress with room to write
      LZ4F_resetDecompressionContext(ctx_);
      throw InputError(path, 0,
                       where + (consumed == n ? ": truncated LZ4 frame (" + num(n) + " compressed bytes end mid-frame)"
                                              : ": LZ4 decoder stopped at compressed byte " + num(consumed)),
                       expected);
    }
  }
  out->resize(produced);
}

ZstdFrameDecoder::ZstdFrameDecoder() : ctx_(ZSTD_createDCtx()) {}

ZstdFrameDecoder::~ZstdFrameDecoder() { ZSTD_freeDCtx(ctx_); }

void ZstdFrameDecoder::decode(const uint8_t* src, size_t n, std::vector<uint8_t>* out, const DecompressLimit& limit,
                              const std::string& path, const std::string& where, const char* expected) {
  if (ctx_ == nullptr) throw InputError(path, 0, where + ": cannot create a Zstd decompression context");
  ZSTD_DCtx_reset(ctx_, ZSTD_reset_session_only);
  out->resize(std::min(limit.max_bytes, std::max<size_t>(n * 4, 1 << 16)));
  ZSTD_inBuffer in{src, n, 0};
  size_t produced = 0;
  bool in_frame = false;
  while (in.pos < in.size || in_frame) {
    if (produced == out->size()) grow(out, limit, path, where, "Zstd");
    ZSTD_outBuffer ob{out->data(), out->size(), produced};
    const size_t before_in = in.pos;
    const size_t r = ZSTD_decompressStream(ctx_, &ob, &in);
    if (ZSTD_isError(r)) {
      ZSTD_DCtx_reset(ctx_, ZSTD_reset_session_only);
      throw InputError(path, 0,
                       where + ": corrupt Zstd data near compressed byte " + num(in.pos) + " (" + ZSTD_getErrorName(r) + ")",
                       expected);
    }
    const bool progress = ob.pos != produced || in.pos != before_in;
    produced = ob.pos;
    in_frame = r != 0;
    if (in_frame && !progress && produced < out->size()) {  // no progress with room to write
      ZSTD_DCtx_reset(ctx_, ZSTD_reset_session_only);
      throw InputError(path, 0,
                       where + (in.pos == in.size ? ": truncated Zstd frame (" + num(n) + " compressed bytes end mid-frame)"
                                                  : ": Zstd decoder stopped at compressed byte " + num(in.pos)),
                       expected);
    }
  }
  out->resize(produced);
}

}  // namespace evio::detail
