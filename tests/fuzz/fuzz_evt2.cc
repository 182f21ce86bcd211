// libFuzzer target: the Prophesee RAW EVT 2.0 reader (format fixed to evt2) and Evt2Decoder.
#include "fuzz_evt_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return evio_fuzz::fuzz_evt<evio::Evt2Decoder>(data, size, evio::DatasetFormat::kEvt2);
}
