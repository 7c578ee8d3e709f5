/*
 * The FMU state format of every fullpose FMU, in memory and serialized alike: this header,
 * then the model struct (the payload, so a state's last model_size bytes are the model:
 * host/fp_controller_api.c reads it there).  The payload holds the model's `initialized`
 * marker (an int32_t at FpModelInfo.initialized_offset, kept by the glue), which the
 * header's lifecycle state must agree with: a model saved before the end of initialization
 * never passes for one after it, nor the reverse.  Every field is naturally aligned and in the
 * byte order of the machine that saved it (the endianness marker tells).  The checksum is
 * 64-bit FNV-1a over the header with the checksum field zeroed, then the payload.
 *
 * No FMI type here: the FMI glue (fmi2_fmustate.c; an FMI 3.0 glue alike) writes and checks
 * states through these functions and logs what they say.
 */
#ifndef FP_FMU_STATE_H
#define FP_FMU_STATE_H

#include <stddef.h>
#include <stdint.h>

#include "fp_model.h"

/* The lifecycle states of an FMU instance (FMI 2.0 co-simulation, spec section 4.2.4, and
 * Model Exchange, section 3.2.3: Event Mode and Continuous-Time Mode): one bit each, as the
 * glue's state machine and a saved state's header hold them. */
enum {
    S_INSTANTIATED = 1 << 0,
    S_INIT = 1 << 1,
    S_STEP_COMPLETE = 1 << 2,
    S_STEP_FAILED = 1 << 3,
    S_TERMINATED = 1 << 4,
    S_ERROR = 1 << 5,
    S_FATAL = 1 << 6,
    S_EVENT_MODE = 1 << 7,
    S_CONTINUOUS_TIME = 1 << 8
};
/* the states of a Model Exchange instance after initialization, before termination */
#define S_ME_RUNNING (S_EVENT_MODE | S_CONTINUOUS_TIME)
#define S_ANY_BUT_FATAL                                                                  \
    (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED | S_ERROR | \
     S_ME_RUNNING)
/* a saved state's payload is a model after initialization */
#define S_INITIALIZED (S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED | S_ME_RUNNING)

/* The name of one lifecycle state ("Instantiated", ...). */
const char *fp_lifecycle_name(int state);

#define STATE_MAGIC "FPST"
#define STATE_MAGIC_V1 "FPS1" /* format 1: unversioned, unchecked (before this one) */
/* 3: the payload carries the initialized marker (format 2 had padding there; the header is
 * the same) */
#define STATE_VERSION 3u
#define STATE_ENDIAN 0x0102u
#define STATE_FLAG_DIRTY 1u          /* parameters changed since the last initialize */
#define STATE_FLAG_TUNABLES_DIRTY 2u /* tunable parameters changed while stepping */
#define STATE_FLAGS_KNOWN (STATE_FLAG_DIRTY | STATE_FLAG_TUNABLES_DIRTY)

typedef struct {
    char magic[4];         /*  0: "FPST" */
    uint16_t version;      /*  4: format version, 3 */
    uint16_t endian;       /*  6: 0x0102 as the saving machine stores it */
    uint32_t header_size;  /*  8: sizeof(StateHeader), 80 */
    uint32_t payload_size; /* 12: sizeof the model struct */
    char guid[40];         /* 16: the FMU's GUID, NUL-terminated */
    int32_t state;         /* 56: lifecycle state, one S_* bit */
    uint32_t flags;        /* 60: STATE_FLAG_* */
    double time;           /* 64: the FMU's time */
    uint64_t checksum;     /* 72: FNV-1a 64 over header (this field 0) and payload */
} StateHeader;

/* Size in bytes of a state of a model of model_size bytes. */
size_t fp_state_size(size_t model_size);

/* Write a state into buf (fp_state_size bytes): the header of these fields, the model. */
void fp_state_write(unsigned char *buf, const char *guid, int32_t state, uint32_t flags,
                    double time, const void *model, size_t model_size);

/* How much of a state fp_state_check verifies. */
enum {
    STATE_HEADER = 0, /* magic, version, byte order, sizes, FMU identity: before reusing,
                         sizing or freeing a state (the payload is not read) */
    STATE_ALL = 1     /* and the checksum and the lifecycle fields, the lifecycle against the
                         payload's initialized marker: before reading it */
};

/*
 * Checks a state buffer before anything reads or writes beyond what is checked: the magic
 * first (4 bytes), then the header, then (STATE_ALL) header and payload.  `size` is the
 * buffer's size when the caller knows it (serialized data), 0 for a state this FMU
 * allocated (whose size the header must confirm).  `guid`, `model_name`, `model_size` and
 * `initialized_offset` (where the model's int32_t initialized marker is) are the FMU's.
 * FP_OK with *out filled (when not NULL), or FP_ERROR with the reason in why (a phrase to
 * follow the name of what was checked: "is truncated: ...").
 */
FpStatus fp_state_check(const unsigned char *buf, size_t size, int level, const char *guid,
                        const char *model_name, size_t model_size, size_t initialized_offset,
                        StateHeader *out, char *why, size_t why_size);

#endif
