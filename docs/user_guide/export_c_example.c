/* estimate.c: filter recordings read as CSV on stdin, print the estimates as CSV on stdout.
 *
 * Input: a header line, then one line per sample, in time order: the recording id (text
 * without commas), then the model's inputs in its order (skhmmgmr_model_input_name). The
 * filter restarts whenever the recording id changes. An empty field or "nan" is a missing
 * input: the sample is held (code 1).
 * Output: a header line, then estimate_0.., std_0.. and the update's return code per sample.
 *
 * Build with the generated skhmmgmr_model.h and skhmmgmr_model.c (double or float32: the
 * numbers are the filter's own, skhmmgmr_model_real):
 *   cc -std=c99 -O2 -Wall -Wextra -Werror -pedantic -o estimate estimate.c skhmmgmr_model.c -lm
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "skhmmgmr_model.h"

#define N_INPUTS SKHMMGMR_MODEL_N_INPUTS
#define N_OUTPUTS SKHMMGMR_MODEL_N_OUTPUTS

/* Read the inputs after the recording id; returns 0 unless the line holds N_INPUTS numbers. */
static int read_inputs(const char *field, skhmmgmr_model_real *inputs)
{
    char *end;
    int i;
    for (i = 0; i < N_INPUTS; ++i) {
        if (*field != ',') {
            return 0;
        }
        ++field;
        inputs[i] = (skhmmgmr_model_real)strtod(field, &end);
        if (end == field) {
            inputs[i] = (skhmmgmr_model_real)NAN; /* an empty field */
        }
        field = end;
    }
    return *field == '\0' || *field == '\n' || *field == '\r';
}

int main(void)
{
    static char line[1 << 16];
    char recording[256] = "";
    skhmmgmr_model_real inputs[N_INPUTS], estimate[N_OUTPUTS], std[N_OUTPUTS];
    skhmmgmr_model_state state; /* the filter state: on the stack, no heap */
    long number = 1;
    int i, code;

    if (fgets(line, sizeof line, stdin) == NULL) {
        return 0; /* no header: nothing to filter */
    }
    for (i = 0; i < N_OUTPUTS; ++i) {
        printf("estimate_%d,", i);
    }
    for (i = 0; i < N_OUTPUTS; ++i) {
        printf("std_%d,", i);
    }
    printf("code\n");
    while (fgets(line, sizeof line, stdin) != NULL) {
        size_t length = strcspn(line, ",\r\n");
        ++number;
        if (length >= sizeof recording || !read_inputs(line + length, inputs)) {
            fprintf(stderr, "line %ld: expected a recording id and %d inputs\n", number,
                    N_INPUTS);
            return 1;
        }
        if (number == 2 || strlen(recording) != length || strncmp(line, recording, length) != 0) {
            memcpy(recording, line, length);
            recording[length] = '\0';
            skhmmgmr_model_reset(&state); /* a new recording */
        }
        code = skhmmgmr_model_update(&state, inputs, estimate, std);
        for (i = 0; i < N_OUTPUTS; ++i) {
            printf("%.17g,", (double)estimate[i]);
        }
        for (i = 0; i < N_OUTPUTS; ++i) {
            printf("%.17g,", (double)std[i]);
        }
        printf("%d\n", code);
    }
    return 0;
}
