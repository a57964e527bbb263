// Keeps perf_bench_gpu loadable on glibc 2.35 (e.g. Ubuntu 22.04 CUDA images): the static
// libstdc++ of GCC 12 built against glibc 2.36 references arc4random (std::random_device, which
// the benchmark never uses, pulled in through libstdc++'s string instantiations), and the
// dynamic loader refuses a binary that asks for GLIBC_2.36. Defined here, the reference resolves
// inside the binary. getrandom() exists since glibc 2.25.
#include <sys/random.h>

#include <cstdint>

extern "C" uint32_t arc4random(void) {
  uint32_t v = 0;
  while (getrandom(&v, sizeof(v), 0) != static_cast<ssize_t>(sizeof(v))) {
  }
  return v;
}
