/* The end of an FMU's one translation unit (see fp_unity_begin.h). */
#ifndef FP_UNITY_END_H
#define FP_UNITY_END_H

#if defined(FP_UNITY_HIDDEN)
#pragma GCC visibility pop
#endif

#endif
