// Lower bounds on decoding PNG and JPEG frames (issue 48), measured with C libraries and a
// prototype inflate of our own, on the same files held in memory, one thread, CPU time.
//
//   cc -O2 -march=native -o bounds bounds.c -ljpeg -ldeflate -lz
//   ./bounds DIR/*.jpg      # libjpeg-turbo: full decode, entropy decoding alone
//   ./bounds DIR/*.png      # the IDAT stream inflated: libdeflate, zlib, the prototype
//
// JPEG. Every coefficient is Huffman-coded in sequence, so no exact decoder can skip the
// entropy decoding. Two measures of it with libjpeg-turbo: decoding at 1/8 scale (all the
// entropy decoding, a DC-only inverse DCT) and jpeg_read_coefficients (entropy decoding into
// coefficient arrays, no inverse DCT).
//
// PNG. The inflate of the concatenated IDAT data alone (no unfiltering). "multi-literal" is a
// prototype whose 12-bit table entries hold up to three literals, for the noise-dominated
// streams of star frames (nearly all literals); it checks its output against libdeflate's.
// Debian: libjpeg62-turbo-dev, libdeflate-dev, zlib1g-dev.
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
// After stdio.h: jpeglib.h uses size_t and FILE without including their headers.
#include <jpeglib.h>
#include <libdeflate.h>
#include <zlib.h>

static double cpu_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

static uint8_t *slurp(const char *path, size_t *n) {
    FILE *f = fopen(path, "rb");
    if (!f) { perror(path); exit(2); }
    fseek(f, 0, SEEK_END);
    *n = (size_t)ftell(f);
    fseek(f, 0, SEEK_SET);
    uint8_t *b = malloc(*n + 16);
    if (fread(b, 1, *n, f) != *n) { perror(path); exit(2); }
    fclose(f);
    return b;
}

// ---- JPEG -------------------------------------------------------------------------------

enum jpeg_mode { FULL, EIGHTH, COEFFICIENTS };

static long jpeg_once(const uint8_t *b, size_t n, uint8_t *out, enum jpeg_mode mode) {
    struct jpeg_decompress_struct c;
    struct jpeg_error_mgr e;
    c.err = jpeg_std_error(&e);
    jpeg_create_decompress(&c);
    jpeg_mem_src(&c, (unsigned char *)b, (unsigned long)n);
    jpeg_read_header(&c, TRUE);
    long seen = 0;
    if (mode == COEFFICIENTS) {
        seen = (long)(jpeg_read_coefficients(&c) != NULL);
    } else {
        c.out_color_space = JCS_GRAYSCALE;
        if (mode == EIGHTH) { c.scale_num = 1; c.scale_denom = 8; }
        jpeg_start_decompress(&c);
        while (c.output_scanline < c.output_height) {
            uint8_t *row = out + (size_t)c.output_scanline * c.output_width;
            jpeg_read_scanlines(&c, &row, 1);
        }
        seen = out[0];
    }
    jpeg_finish_decompress(&c);
    jpeg_destroy_decompress(&c);
    return seen;
}

// ---- PNG: the prototype inflate ---------------------------------------------------------

#define FAST_BITS 12 // the multi-literal table's index
#define ONE_BITS 12  // the one-symbol tables' index; longer codes are decoded bit by bit

typedef struct {
    const uint8_t *p, *end;
    uint64_t buf;
    int n;
} Bits;

static inline void refill(Bits *b) {
    if (b->p + 8 <= b->end) {
        uint64_t v;
        memcpy(&v, b->p, 8);
        b->buf |= v << b->n;
        b->p += (63 - b->n) >> 3;
        b->n |= 56;
    } else {
        while (b->n <= 56) {
            uint64_t v = b->p < b->end ? *b->p : 0;
            b->p++;
            b->buf |= v << b->n;
            b->n += 8;
        }
    }
}

static inline uint32_t take(Bits *b, int k) {
    uint32_t v = (uint32_t)(b->buf & ((1ull << k) - 1));
    b->buf >>= k;
    b->n -= k;
    return v;
}

// A canonical code: counts by length and symbols in code order (for codes past ONE_BITS).
typedef struct {
    uint16_t count[16], symbol[320];
} Canonical;

typedef struct {
    uint32_t one[1 << ONE_BITS]; // symbol | length << 16 (length 0: longer than ONE_BITS)
    Canonical canonical;
} Code;

static void build_code(Code *c, const uint8_t *lens, int n) {
    uint16_t next[16], offs[16];
    memset(c->canonical.count, 0, sizeof c->canonical.count);
    for (int i = 0; i < n; i++) c->canonical.count[lens[i]]++;
    c->canonical.count[0] = 0;
    offs[1] = 0;
    for (int l = 1; l < 15; l++) offs[l + 1] = offs[l] + c->canonical.count[l];
    for (int i = 0; i < n; i++)
        if (lens[i]) c->canonical.symbol[offs[lens[i]]++] = i;
    // The first code of each length (RFC 1951, 3.2.2).
    int code = 0;
    for (int l = 1; l < 16; l++) {
        code = (code + c->canonical.count[l - 1]) << 1;
        next[l] = code;
    }
    for (int x = 0; x < (1 << ONE_BITS); x++) c->one[x] = 0;
    for (int i = 0; i < n; i++) {
        int l = lens[i];
        if (!l) continue;
        int v = next[l]++, rev = 0;
        for (int k = 0; k < l; k++) rev |= ((v >> k) & 1) << (l - 1 - k);
        if (l > ONE_BITS) continue;
        for (int x = rev; x < (1 << ONE_BITS); x += 1 << l) c->one[x] = i | (l << 16);
    }
}

static inline int decode(Bits *b, const Code *c) {
    uint32_t e = c->one[b->buf & ((1 << ONE_BITS) - 1)];
    if (e >> 16) {
        take(b, e >> 16);
        return e & 0xffff;
    }
    int code = 0, first = 0, index = 0; // bit by bit (puff's method)
    for (int l = 1; l < 16; l++) {
        code |= take(b, 1);
        int n = c->canonical.count[l];
        if (code - n < first) return c->canonical.symbol[index + (code - first)];
        index += n;
        first = (first + n) << 1;
        code <<= 1;
    }
    return -1;
}

// Entry: bits consumed (0-4), literals held (5-6; 0: take the one-symbol path), literals (8-31).
static uint32_t fast[1 << FAST_BITS];

static void build_fast(const Code *lit) {
    for (int x = 0; x < (1 << FAST_BITS); x++) {
        int used = 0, held = 0;
        uint32_t lits = 0;
        while (held < 3) {
            uint32_t e = lit->one[(x >> used) & ((1 << ONE_BITS) - 1)];
            int s = e & 0xffff, l = e >> 16;
            if (l == 0 || s >= 256 || used + l > FAST_BITS) break;
            lits |= (uint32_t)s << (8 * held);
            used += l;
            held++;
        }
        fast[x] = held ? (uint32_t)used | (uint32_t)held << 5 | lits << 8 : 0;
    }
}

static const uint16_t LEN_BASE[29] = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,  15,  17,  19,  23, 27,
                                      31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
static const uint8_t LEN_EXTRA[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                      2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
static const uint16_t DIST_BASE[30] = {1,    2,    3,    4,    5,    7,     9,     13,    17,  25,
                                       33,   49,   65,   97,   129,  193,   257,   385,   513, 769,
                                       1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
static const uint8_t DIST_EXTRA[30] = {0, 0, 0, 0, 1, 1, 2, 2,  3,  3,  4,  4,  5,  5,  6,
                                       6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};

static Code lit_code, dist_code;
static long blocks;

// Inflates a zlib stream into out (room for its whole output, + 4 bytes); its length.
static long inflate_multi(const uint8_t *in, size_t n, uint8_t *out) {
    Bits b = {in + 2, in + n, 0, 0};
    uint8_t *o = out;
    int last = 0;
    while (!last) {
        refill(&b);
        last = take(&b, 1);
        int type = take(&b, 2);
        uint8_t lens[320];
        if (type == 0) {
            take(&b, b.n & 7);
            b.p -= b.n >> 3; // give back the whole bytes read ahead
            b.buf = 0;
            b.n = 0;
            uint16_t len = b.p[0] | b.p[1] << 8;
            b.p += 4;
            memcpy(o, b.p, len);
            o += len;
            b.p += len;
            continue;
        } else if (type == 1) {
            for (int i = 0; i < 288; i++) lens[i] = i < 144 ? 8 : i < 256 ? 9 : i < 280 ? 7 : 8;
            for (int i = 0; i < 30; i++) lens[288 + i] = 5;
            build_code(&lit_code, lens, 288);
            build_code(&dist_code, lens + 288, 30);
        } else {
            static const uint8_t ORDER[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
            int hlit = take(&b, 5) + 257, hdist = take(&b, 5) + 1, hclen = take(&b, 4) + 4;
            uint8_t cl[19] = {0};
            refill(&b);
            for (int i = 0; i < hclen; i++) {
                cl[ORDER[i]] = take(&b, 3);
                if (i == 9) refill(&b);
            }
            static Code cl_code;
            build_code(&cl_code, cl, 19);
            for (int i = 0; i < hlit + hdist;) {
                refill(&b);
                int s = decode(&b, &cl_code);
                if (s < 16) lens[i++] = s;
                else if (s == 16) for (int r = 3 + take(&b, 2); r--; i++) lens[i] = lens[i - 1];
                else if (s == 17) for (int r = 3 + take(&b, 3); r--;) lens[i++] = 0;
                else for (int r = 11 + take(&b, 7); r--;) lens[i++] = 0;
            }
            build_code(&lit_code, lens, hlit);
            build_code(&dist_code, lens + hlit, hdist);
        }
        blocks++;
        build_fast(&lit_code);
        for (;;) {
            refill(&b);
            uint32_t e = fast[b.buf & ((1 << FAST_BITS) - 1)];
            if (e & 0x60) { // up to three literals, twice per refill
                uint32_t v = e >> 8;
                memcpy(o, &v, 4);
                o += (e >> 5) & 3;
                b.buf >>= e & 31;
                b.n -= e & 31;
                e = fast[b.buf & ((1 << FAST_BITS) - 1)];
                if (e & 0x60) {
                    v = e >> 8;
                    memcpy(o, &v, 4);
                    o += (e >> 5) & 3;
                    b.buf >>= e & 31;
                    b.n -= e & 31;
                }
                continue;
            }
            int sym = decode(&b, &lit_code);
            if (sym < 256) { *o++ = (uint8_t)sym; continue; }
            if (sym == 256) break;
            sym -= 257;
            int len = LEN_BASE[sym] + take(&b, LEN_EXTRA[sym]);
            refill(&b);
            int ds = decode(&b, &dist_code);
            int dist = DIST_BASE[ds] + take(&b, DIST_EXTRA[ds]);
            for (int k = 0; k < len; k++) o[k] = o[k - dist];
            o += len;
        }
    }
    return (long)(o - out);
}

static uint32_t be32(const uint8_t *p) { return (uint32_t)p[0] << 24 | p[1] << 16 | p[2] << 8 | p[3]; }

// The concatenated IDAT data of a PNG and the size of its filtered rows.
static uint8_t *idat(const uint8_t *b, size_t n, size_t *len, size_t *raw) {
    uint8_t *z = malloc(n);
    size_t p = 8;
    *len = 0;
    while (p + 12 <= n) {
        uint32_t l = be32(b + p);
        if (!memcmp(b + p + 4, "IHDR", 4)) {
            uint32_t w = be32(b + p + 8), h = be32(b + p + 12), depth = b[p + 16];
            *raw = (size_t)h * (1 + w * (depth / 8));
        }
        if (!memcmp(b + p + 4, "IDAT", 4)) { memcpy(z + *len, b + p + 8, l); *len += l; }
        p += 12 + l;
    }
    return z;
}

int main(int argc, char **argv) {
    int nf = argc - 1;
    if (nf < 1) { fprintf(stderr, "usage: bounds FILE.jpg... | FILE.png...\n"); return 2; }
    int is_png = strstr(argv[1], ".png") != NULL;
    uint8_t **data = malloc(nf * sizeof *data);
    size_t *len = malloc(nf * sizeof *len), raw = 0, file_bytes = 0;
    for (int i = 0; i < nf; i++) {
        size_t n;
        uint8_t *b = slurp(argv[i + 1], &n);
        file_bytes += n;
        data[i] = is_png ? idat(b, n, &len[i], &raw) : b;
        if (is_png) free(b);
        else len[i] = n;
    }
    uint8_t *out = malloc(64 << 20), *ref = malloc(64 << 20);
    struct libdeflate_decompressor *d = libdeflate_alloc_decompressor();
    if (is_png)
        for (int i = 0; i < nf; i++) {
            size_t got;
            if (libdeflate_zlib_decompress(d, data[i], len[i], ref, raw, &got) || got != raw) {
                fprintf(stderr, "%s: not one inflatable stream\n", argv[i + 1]);
                return 1;
            }
            if (inflate_multi(data[i], len[i], out) != (long)raw || memcmp(out, ref, raw)) {
                fprintf(stderr, "%s: the prototype's bytes differ\n", argv[i + 1]);
                return 1;
            }
        }
    printf("%d files, %.0f kB a file; ms a frame, CPU time, 5 rounds\n", nf, file_bytes / 1e3 / nf);
    for (int r = 0; r < 5; r++) {
        double t[5];
        long sum = 0;
        t[0] = cpu_s();
        if (is_png) {
            size_t got;
            for (int i = 0; i < nf; i++) sum += libdeflate_zlib_decompress(d, data[i], len[i], out, raw, &got);
            t[1] = cpu_s();
            for (int i = 0; i < nf; i++) {
                uLongf ol = raw;
                sum += uncompress(out, &ol, data[i], len[i]);
            }
            t[2] = cpu_s();
            blocks = 0;
            for (int i = 0; i < nf; i++) sum += inflate_multi(data[i], len[i], out);
            t[3] = cpu_s();
            for (int i = 0; i < nf; i++) { memcpy(out, data[i], len[i]); sum += out[1]; }
            t[4] = cpu_s();
            printf("  inflate: libdeflate %.3f  zlib %.3f  multi-literal %.3f (%.1f blocks a frame)  "
                   "memory copy %.3f   [%ld]\n",
                   (t[1] - t[0]) * 1e3 / nf, (t[2] - t[1]) * 1e3 / nf, (t[3] - t[2]) * 1e3 / nf,
                   (double)blocks / nf, (t[4] - t[3]) * 1e3 / nf, sum % 7);
        } else {
            for (int i = 0; i < nf; i++) sum += jpeg_once(data[i], len[i], out, FULL);
            t[1] = cpu_s();
            for (int i = 0; i < nf; i++) sum += jpeg_once(data[i], len[i], out, EIGHTH);
            t[2] = cpu_s();
            for (int i = 0; i < nf; i++) sum += jpeg_once(data[i], len[i], out, COEFFICIENTS);
            t[3] = cpu_s();
            for (int i = 0; i < nf; i++) { memcpy(out, data[i], len[i]); sum += out[1]; }
            t[4] = cpu_s();
            printf("  libjpeg-turbo: full %.3f  1/8 scale (entropy + DC) %.3f  coefficients only %.3f  "
                   "memory copy %.3f   [%ld]\n",
                   (t[1] - t[0]) * 1e3 / nf, (t[2] - t[1]) * 1e3 / nf, (t[3] - t[2]) * 1e3 / nf,
                   (t[4] - t[3]) * 1e3 / nf, sum % 7);
        }
    }
    return 0;
}
