# fp_fmi2_headers(FROM_DIR TO_DIR): the three FMI 2.0 headers every FMU's sources/ carries and
# its glue is compiled with, in TO_DIR, from the installed fmpy package's FROM_DIR (never from
# this repository).  fmi2FunctionTypes.h and fmi2TypesPlatform.h are copied as they are.
# fmpy's fmi2Functions.h is the FMI 2.0.1 standard's with two blocks edited, each marked by
# fmpy ("This definition has been changed ..."): it always exports the functions and ignores
# FMI2_FUNCTION_PREFIX, so two FMUs cannot be compiled into one image.  Those two blocks are
# put back as the standard has them, and nothing else changes: the result is the FMI 2.0.1
# fmi2Functions.h byte for byte (with LF line ends; tests/test_fmus/test_source_builds.py holds
# its SHA-256).  A header that already honours the prefix is copied as it is; any other is
# refused.  Files are rewritten only when their content changes.

set(FP_FMPY_FMI2_EDIT [==[
/*
Export FMI2 API functions on Windows and under GCC. 
This definition has been changed to always export the symbols.
*/
#if defined _WIN32 || defined __CYGWIN__
    /* Note: both gcc & MSVC on Windows support this syntax. */
    #define FMI2_Export __declspec(dllexport)
#else
    #if __GNUC__ >= 4
    #define FMI2_Export __attribute__ ((visibility ("default")))
    #else
    #define FMI2_Export
    #endif
#endif


/* 
Macro to construct the real function name.
This definition has been changed to add no prefix.
*/
#define fmi2FullName(name) name

]==])
set(FP_FMI2_STANDARD [==[
/*
  Export FMI2 API functions on Windows and under GCC.
  If custom linking is desired then the FMI2_Export must be
  defined before including this file. For instance,
  it may be set to __declspec(dllimport).
*/
#if !defined(FMI2_Export)
  #if !defined(FMI2_FUNCTION_PREFIX)
    #if defined _WIN32 || defined __CYGWIN__
     /* Note: both gcc & MSVC on Windows support this syntax. */
        #define FMI2_Export __declspec(dllexport)
    #else
      #if __GNUC__ >= 4
        #define FMI2_Export __attribute__ ((visibility ("default")))
      #else
        #define FMI2_Export
      #endif
    #endif
  #else
    #define FMI2_Export
  #endif
#endif

/* Macros to construct the real function name
   (prepend function name by FMI2_FUNCTION_PREFIX) */
#if defined(FMI2_FUNCTION_PREFIX)
  #define fmi2Paste(a,b)     a ## b
  #define fmi2PasteB(a,b)    fmi2Paste(a,b)
  #define fmi2FullName(name) fmi2PasteB(FMI2_FUNCTION_PREFIX, name)
#else
  #define fmi2FullName(name) name
#endif
]==])

function(fp_fmi2_headers from to)
  file(READ "${from}/fmi2Functions.h" text)
  string(FIND "${text}" "${FP_FMPY_FMI2_EDIT}" at)
  if(NOT at EQUAL -1)
    string(REPLACE "${FP_FMPY_FMI2_EDIT}" "${FP_FMI2_STANDARD}" text "${text}")
  elseif(NOT text MATCHES "fmi2PasteB\\(FMI2_FUNCTION_PREFIX, name\\)")
    message(FATAL_ERROR "${from}/fmi2Functions.h ignores FMI2_FUNCTION_PREFIX and is not the "
                        "edit of the FMI 2.0 header known from fmpy 0.3.32: cannot restore it")
  endif()
  file(WRITE "${to}/fmi2Functions.h.new" "${text}")
  configure_file("${to}/fmi2Functions.h.new" "${to}/fmi2Functions.h" COPYONLY)
  file(REMOVE "${to}/fmi2Functions.h.new")
  foreach(header fmi2FunctionTypes.h fmi2TypesPlatform.h)
    configure_file("${from}/${header}" "${to}/${header}" COPYONLY)
  endforeach()
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${from}/fmi2Functions.h")
endfunction()
