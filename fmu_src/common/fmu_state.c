/* The FMU state format (fmu_state.h): writing and checking states, no FMI types. */
#include "fmu_state.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

FP_STATIC_ASSERT(sizeof(StateHeader) == 80, state_header_is_80_bytes);
FP_STATIC_ASSERT(sizeof(StateHeader) % 8 == 0, state_payload_stays_aligned);

const char *fp_lifecycle_name(int state) {
    switch (state) {
    case S_INSTANTIATED: return "Instantiated";
    case S_INIT: return "InitializationMode";
    case S_STEP_COMPLETE: return "StepComplete";
    case S_STEP_FAILED: return "StepFailed";
    case S_TERMINATED: return "Terminated";
    case S_ERROR: return "Error";
    case S_EVENT_MODE: return "EventMode";
    case S_CONTINUOUS_TIME: return "ContinuousTimeMode";
    default: return "Fatal";
    }
}

size_t fp_state_size(size_t model_size) { return sizeof(StateHeader) + model_size; }

static uint64_t state_checksum(const StateHeader *h, const void *payload, size_t n) {
    StateHeader copy = *h;
    copy.checksum = 0;
    return fp_fnv1a64(fp_fnv1a64(FP_FNV1A64_BASIS, &copy, sizeof copy), payload, n);
}

void fp_state_write(unsigned char *buf, const char *guid, int32_t state, uint32_t flags,
                    double time, const void *model, size_t model_size) {
    StateHeader h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, STATE_MAGIC, sizeof h.magic);
    h.version = (uint16_t)STATE_VERSION;
    h.endian = (uint16_t)STATE_ENDIAN;
    h.header_size = (uint32_t)sizeof h;
    h.payload_size = (uint32_t)model_size;
    memcpy(h.guid, guid, sizeof h.guid);
    h.state = state;
    h.flags = flags;
    h.time = time;
    h.checksum = state_checksum(&h, model, model_size);
    memcpy(buf, &h, sizeof h);
    memcpy(buf + sizeof h, model, model_size);
}

static FpStatus refuse(char *why, size_t why_size, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

static FpStatus refuse(char *why, size_t why_size, const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    if (why != NULL && why_size > 0) vsnprintf(why, why_size, fmt, args);
    va_end(args);
    return FP_ERROR;
}

FpStatus fp_state_check(const unsigned char *buf, size_t size, int level, const char *guid,
                        const char *model_name, size_t model_size, size_t initialized_offset,
                        StateHeader *out, char *why, size_t why_size) {
    const char *model = model_name;
    const unsigned long expected = (unsigned long)fp_state_size(model_size);
    const int serialized = size > 0;
    StateHeader h;
    if (buf == NULL) return refuse(why, why_size, "is NULL");
    if (serialized && size < sizeof h.magic)
        return refuse(why, why_size, "is truncated: %lu bytes, a state of %s has %lu bytes",
                      (unsigned long)size, model, expected);
    if (memcmp(buf, STATE_MAGIC, 4) != 0) {
        if (memcmp(buf, STATE_MAGIC_V1, 4) == 0)
            return refuse(why, why_size,
                          "is in state format 1 (FPS1); this FMU reads format %u only",
                          STATE_VERSION);
        if (serialized)
            return refuse(why, why_size,
                          "was not serialized by this model (%s): no \"%s\" magic (%02x %02x "
                          "%02x %02x); %lu bytes, a state of %s has %lu",
                          model, STATE_MAGIC, buf[0], buf[1], buf[2], buf[3],
                          (unsigned long)size, model, expected);
        return refuse(why, why_size,
                      "was not saved by this model (%s): no \"%s\" magic (%02x %02x %02x "
                      "%02x)",
                      model, STATE_MAGIC, buf[0], buf[1], buf[2], buf[3]);
    }
    if (serialized && size < sizeof h)
        return refuse(why, why_size,
                      "is truncated: %lu bytes, shorter than the %lu-byte header (a state of %s "
                      "has %lu bytes)",
                      (unsigned long)size, (unsigned long)sizeof h, model, expected);
    memcpy(&h, buf, sizeof h);
    if (h.version != STATE_VERSION)
        return refuse(why, why_size,
                      "is in state format version %u; this FMU reads version %u only",
                      (unsigned)h.version, STATE_VERSION);
    if (h.endian != STATE_ENDIAN) {
        if (h.endian == (uint16_t)((STATE_ENDIAN >> 8) | ((STATE_ENDIAN & 0xffu) << 8)))
            return refuse(why, why_size, "was saved on a machine of the other byte order");
        return refuse(why, why_size, "is damaged: byte-order marker 0x%04x, expected 0x%04x",
                      (unsigned)h.endian, STATE_ENDIAN);
    }
    if (h.header_size != sizeof h)
        return refuse(why, why_size, "is damaged: header size %lu, expected %lu",
                      (unsigned long)h.header_size, (unsigned long)sizeof h);
    if (memchr(h.guid, '\0', sizeof h.guid) == NULL)
        return refuse(why, why_size, "is damaged: its GUID is not terminated");
    if (strcmp(h.guid, guid) != 0)
        return refuse(why, why_size, "belongs to another FMU (GUID %s), not to this %s (GUID %s)",
                      h.guid, model, guid);
    if (h.payload_size != model_size)
        return refuse(why, why_size, "is damaged: payload of %lu bytes, the model of %s has %lu",
                      (unsigned long)h.payload_size, model, (unsigned long)model_size);
    if (serialized && size != expected)
        return refuse(why, why_size, "is %s: %lu bytes, its header says %lu",
                      size < expected ? "truncated" : "too long", (unsigned long)size, expected);
    if (level == STATE_ALL) {
        uint64_t sum = state_checksum(&h, buf + sizeof h, h.payload_size);
        int initialized = (h.state & S_INITIALIZED) != 0;
        int32_t marker;
        if (sum != h.checksum)
            return refuse(why, why_size,
                          "is damaged: checksum mismatch (stored %016llx, computed %016llx)",
                          (unsigned long long)h.checksum, (unsigned long long)sum);
        if (!(h.state & S_ANY_BUT_FATAL) || (h.state & (h.state - 1)) != 0)
            return refuse(why, why_size, "is damaged: lifecycle state 0x%x is not one FMI state",
                          (unsigned)h.state);
        if ((h.flags & ~STATE_FLAGS_KNOWN) != 0 ||
            (initialized && (h.flags & STATE_FLAG_DIRTY)) ||
            ((h.state & (S_INSTANTIATED | S_INIT)) && (h.flags & STATE_FLAG_TUNABLES_DIRTY)))
            return refuse(why, why_size,
                          "is damaged: flags 0x%x do not fit its lifecycle state %s",
                          (unsigned)h.flags, fp_lifecycle_name(h.state));
        if (!isfinite(h.time)) return refuse(why, why_size, "is damaged: its time is not finite");
        /* the lifecycle against the model it holds: relabelling a header (and resealing the
         * checksum) cannot make a model never initialized pass for one that was, nor the
         * reverse; Error follows either */
        if (h.payload_size < sizeof marker || initialized_offset > h.payload_size - sizeof marker)
            return refuse(why, why_size,
                          "cannot be checked: the initialized marker at %lu lies beyond the "
                          "%lu-byte model",
                          (unsigned long)initialized_offset, (unsigned long)h.payload_size);
        memcpy(&marker, buf + sizeof h + initialized_offset, sizeof marker);
        if (marker != 0 && marker != 1)
            return refuse(why, why_size,
                          "is damaged: its model's initialized marker is %ld, neither 0 nor 1",
                          (long)marker);
        if ((h.state & S_ERROR) == 0 && marker != initialized)
            return refuse(why, why_size,
                          "is damaged: its model was saved %s the end of initialization, its "
                          "lifecycle state %s is not",
                          marker ? "after" : "before", fp_lifecycle_name(h.state));
    }
    if (out != NULL) *out = h;
    return FP_OK;
}
