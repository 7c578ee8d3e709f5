/*
 * Export marker of the host C API: the functions the Python packages call through ctypes
 * (fp_multirotor_api.h, fp_controller_api.h, fp_cosim.h).  Everything else in a library
 * stays hidden (the build compiles with hidden visibility).  Every exported function
 * returns int: 0 on success, a non-zero FpStatus (or FMI status) otherwise.
 */
#ifndef FP_API_H
#define FP_API_H

#if defined(_WIN32)
#define FP_API __declspec(dllexport)
#else
#define FP_API __attribute__((visibility("default")))
#endif

#endif
