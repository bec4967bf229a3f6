/*
 * A stand-in for Pico Technology's libusbtc08, for dry runs of the whole receiver.
 *
 * It exports the seven functions the driver binds (reach_receiver/transports/tc08_library.py)
 * with the vendor's C signatures, so the driver's real ctypes binding is exercised. The
 * "unit" reads its nine temperatures (cold junction, channels 1-8, degrees C) from a text
 * file next to this library, "<library path>.values", which the simulated receiver
 * rewrites atomically as its physics evolves. Each reading adds thermocouple noise
 * (about 0.05 K rms, a fixed-seed generator), as a real unit's readings always jitter.
 * No USB is involved.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define N_CHANNELS 9
#define HANDLE 1
#define ERROR_OK 0
#define ERROR_INVALID_PARAMETER 5
#define ERROR_NOT_RESPONDING 4
#define UNITS_KELVIN 2

static int opened = 0;
static int16_t last_error = ERROR_OK;
static char enabled[N_CHANNELS];
static uint32_t noise_state = 0x12345678u;

/* Roughly Gaussian noise of 0.05 K rms: the sum of four uniforms (xorshift32). */
static float thermocouple_noise(void) {
    float sum = 0.0f;
    for (int i = 0; i < 4; i++) {
        noise_state ^= noise_state << 13;
        noise_state ^= noise_state >> 17;
        noise_state ^= noise_state << 5;
        sum += (float)noise_state / 4294967296.0f - 0.5f;
    }
    return sum * 0.0866f; /* 4 uniforms: variance 1/3; 0.05 / sqrt(1/3) */
}

static int values_path(char *out, size_t size) {
    Dl_info info;
    if (!dladdr((void *)values_path, &info) || info.dli_fname == NULL) return 0;
    return snprintf(out, size, "%s.values", info.dli_fname) < (int)size;
}

int16_t usb_tc08_open_unit(void) {
    char path[4096];
    FILE *file;
    if (!values_path(path, sizeof path) || (file = fopen(path, "r")) == NULL) {
        return 0; /* no unit found */
    }
    fclose(file);
    opened = 1;
    memset(enabled, 0, sizeof enabled);
    return HANDLE;
}

static int valid(int16_t handle) {
    if (handle != HANDLE || !opened) {
        last_error = ERROR_INVALID_PARAMETER;
        return 0;
    }
    return 1;
}

int16_t usb_tc08_close_unit(int16_t handle) {
    if (!valid(handle)) return 0;
    opened = 0;
    return 1;
}

int16_t usb_tc08_set_mains(int16_t handle, int16_t sixty_hertz) {
    (void)sixty_hertz;
    return (int16_t)valid(handle);
}

int16_t usb_tc08_set_channel(int16_t handle, int16_t channel, int8_t tc_type) {
    if (!valid(handle)) return 0;
    if (channel < 0 || channel >= N_CHANNELS) {
        last_error = ERROR_INVALID_PARAMETER;
        return 0;
    }
    enabled[channel] = tc_type != ' ';
    return 1;
}

int16_t usb_tc08_get_single(int16_t handle, float *temp, int16_t *overflow_flags, int16_t units) {
    char path[4096];
    float values[N_CHANNELS];
    FILE *file;
    int n = 0;
    if (!valid(handle)) return 0;
    if (!values_path(path, sizeof path) || (file = fopen(path, "r")) == NULL) {
        last_error = ERROR_NOT_RESPONDING;
        return 0;
    }
    while (n < N_CHANNELS && fscanf(file, "%f", &values[n]) == 1) n++;
    fclose(file);
    if (n != N_CHANNELS) {
        last_error = ERROR_NOT_RESPONDING;
        return 0;
    }
    for (int i = 0; i < N_CHANNELS; i++) {
        float kelvin_offset = units == UNITS_KELVIN ? 273.15f : 0.0f;
        temp[i] = enabled[i] ? values[i] + kelvin_offset + thermocouple_noise() : 0.0f;
    }
    *overflow_flags = 0;
    return 1;
}

int16_t usb_tc08_get_last_error(int16_t handle) {
    (void)handle;
    return last_error;
}

int16_t usb_tc08_get_unit_info2(int16_t handle, int8_t *string, int16_t string_length, int16_t line) {
    const char *lines[] = {"1.0 (stand-in)", "1", "1", "TC-08", "SIM/0001"};
    const char *text;
    size_t length;
    if (!valid(handle) || string_length <= 0) return 0;
    text = (line >= 0 && line < 5) ? lines[line] : "";
    length = strlen(text);
    if (length >= (size_t)string_length) length = (size_t)string_length - 1;
    memcpy(string, text, length);
    string[length] = 0;
    return (int16_t)length;
}
