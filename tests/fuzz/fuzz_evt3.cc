// libFuzzer target: the Prophesee RAW EVT 3.0 reader (format fixed to evt3) and Evt3Decoder.
#include "fuzz_evt_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return evio_fuzz::fuzz_evt<evio::Evt3Decoder>(data, size, evio::DatasetFormat::kEvt3);
}
