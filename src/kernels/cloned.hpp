#pragma once
// KINEMA_CLONED: a function compiled once per instruction set (AVX-512, AVX2, baseline) and
// picked by the loader for this CPU. Only for code whose clones do the same operations, so
// the results are the same bits whichever runs. Not under ThreadSanitizer: the loader runs
// the clones' resolvers before its runtime is up, and the program would not start.

#if defined(__SANITIZE_THREAD__)
#define KINEMA_CLONED
#else
#define KINEMA_CLONED [[gnu::target_clones("avx512f", "avx2", "default")]]
#endif
