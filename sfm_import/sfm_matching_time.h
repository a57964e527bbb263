// How long perf sfm's matching takes, for its choices under a time budget (colmap_runner.h
// SfmOptions::seconds_left): CPU matching of every pair, estimated before any matching from a
// measured rate, and after sequential matching from that step's own rate.
#pragma once

#include "sfm_import/colmap_runner.h"

namespace perf {

// Seconds CPU matching takes per pair of photos with `options`' threads: 0.28 s on 2 threads at
// 8192 features (bonsai, 800 px), scaled by the threads (at most 16).
double PairSeconds(const SfmOptions& options);

// The most photos auto mode matches pair by pair: exhaustive_max_images, and under a time budget
// only as many as take at most half the time it leaves at PairSeconds.
int AutoExhaustiveMax(const SfmOptions& options);

// What matching the pairs sequential matching left (at the rate it matched its own, about
// n (overlap + log2 n) pairs with quadratic overlap) and mapping again would take, in seconds.
double EveryPairSeconds(const SfmOptions& options, int n, double match_seconds, double map_seconds);

// What a whole perf sfm of `photos` photos of `megapixels` each takes in sequence (features,
// matching, mapping, the passes), in seconds: bonsai's 84 at 0.43 MP took 322-428 s on 2 threads,
// about 11.6 s a megapixel a photo; scaled by the threads as PairSeconds is. The ghost repair's
// routes under a time budget use it (ghost_repair.h).
double SequentialSfmSeconds(const SfmOptions& options, int photos, double megapixels);

}  // namespace perf
