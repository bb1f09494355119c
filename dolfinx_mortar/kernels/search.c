/* The broad-phase search's box overlaps (search.candidate_pairs), compiled as its own module
 * (compiled.load("search")). */
#include <float.h>
#include <math.h>
#include <stdlib.h>

typedef struct {
    long key, index;
} keyed_t;

typedef struct {
    long *data;
    long size, capacity;
} pairs_t;

static int compare_keyed(const void *a, const void *b) {
    long x = ((const keyed_t *)a)->key, y = ((const keyed_t *)b)->key;
    return (x > y) - (x < y);
}

static int compare_long(const void *a, const void *b) {
    long x = *(const long *)a, y = *(const long *)b;
    return (x > y) - (x < y);
}

static int push(pairs_t *p, long slave, long master) {
    if (p->size == p->capacity) {
        long capacity = p->capacity ? 2 * p->capacity : 1024;
        long *data = realloc(p->data, sizeof(long) * 2 * (size_t)capacity);
        if (!data) return -1;
        p->data = data;
        p->capacity = capacity;
    }
    p->data[2 * p->size] = slave;
    p->data[2 * p->size + 1] = master;
    ++p->size;
    return 0;
}

/* floor(log2(max_k half_k + margin)), -1100 for a box that is not finite (it pairs with
 * nothing) */
static int size_class(int dim, const double *lower, const double *upper, double margin) {
    double reach = 0.0;
    for (int k = 0; k < dim; ++k) {
        double half = 0.5 * (upper[k] - lower[k]);
        if (!isfinite(half) || !isfinite(lower[k])) return -1100;
        if (half > reach) reach = half;
    }
    reach += margin;
    int exponent;
    frexp(reach > DBL_MIN ? reach : DBL_MIN, &exponent);
    return exponent - 1;
}

/* the boxes of one size class: members and their largest half extent per coordinate */
typedef struct {
    int size_class;
    long count;
    long *members;
    double largest[3];
} group_t;

/* Groups the n boxes by size class (boxes that are not finite overlap nothing and are left
 * out). Returns the number of groups, -1 if out of memory; *groups and *members are
 * allocated here. */
static int group_boxes(long n, int dim, const double *lower, const double *upper,
                       double margin, group_t **groups, long **members) {
    enum { OFFSET = 1100, RANGE = 2200 };
    long *count = calloc(RANGE, sizeof(long));
    int *classes = malloc(sizeof(int) * (size_t)(n > 0 ? n : 1));
    *members = malloc(sizeof(long) * (size_t)(n > 0 ? n : 1));
    *groups = NULL;
    if (!count || !classes || !*members) {
        free(count);
        free(classes);
        return -1;
    }
    for (long i = 0; i < n; ++i) {
        classes[i] = size_class(dim, lower + i * dim, upper + i * dim, margin);
        if (classes[i] > -OFFSET) ++count[classes[i] + OFFSET];
    }
    int num_groups = 0;
    for (int c = 0; c < RANGE; ++c) num_groups += count[c] > 0;
    *groups = calloc((size_t)(num_groups > 0 ? num_groups : 1), sizeof(group_t));
    if (!*groups) {
        free(count);
        free(classes);
        return -1;
    }
    long start = 0;
    int g = 0;
    for (int c = 0; c < RANGE; ++c) {
        if (!count[c]) continue;
        group_t *group = *groups + g++;
        group->size_class = c - OFFSET;
        group->members = *members + start;
        start += count[c];
        count[c] = g;  /* from here: 1 + the group of class c */
    }
    for (long i = 0; i < n; ++i) {
        if (classes[i] <= -OFFSET) continue;
        group_t *group = *groups + count[classes[i] + OFFSET] - 1;
        for (int k = 0; k < dim; ++k) {
            double half = 0.5 * (upper[i * dim + k] - lower[i * dim + k]);
            if (half > group->largest[k]) group->largest[k] = half;
        }
        group->members[group->count++] = i;
    }
    free(count);
    free(classes);
    return num_groups;
}

static int boxes_overlap(int dim, const double *lower_a, const double *upper_a,
                         const double *lower_b, const double *upper_b, double margin) {
    for (int k = 0; k < dim; ++k)
        if (!(lower_a[k] - margin <= upper_b[k] + margin
              && lower_b[k] - margin <= upper_a[k] + margin))
            return 0;
    return 1;
}

static double cell(const double *lower, const double *upper, int k, double width) {
    return floor(0.5 * (lower[k] + upper[k]) / width);
}

/* The pairs of a slave group and a master group whose boxes overlap once grown by margin.
 * Overlapping boxes have centres closer than width_k = largest_s,k + largest_m,k + 2 margin in
 * each coordinate k: the masters are sorted by their cell of a grid of those widths and each
 * slave looks into its cell and the neighbouring ones. */
static int pair_groups(int dim, const group_t *slaves, const group_t *masters,
                       const double *slave_lower, const double *slave_upper,
                       const double *master_lower, const double *master_upper, double margin,
                       keyed_t *sorted, pairs_t *found, long *tested) {
    double width[3] = {1.0, 1.0, 1.0}, low[3], extent[3];
    for (int k = 0; k < dim; ++k) {
        /* (1 + 1e-9: the rounding of the cells loses no pair; the boxes decide) */
        width[k] = (slaves->largest[k] + masters->largest[k] + 2.0 * margin) * (1.0 + 1e-9);
        if (!(width[k] > DBL_MIN)) width[k] = DBL_MIN;
    }
    for (;;) {  /* coarser cells until every key fits in a long */
        double high[3], cells = 1.0;
        for (int k = 0; k < dim; ++k) {
            low[k] = INFINITY;
            high[k] = -INFINITY;
        }
        for (int side = 0; side < 2; ++side) {
            const group_t *group = side ? masters : slaves;
            const double *lower = side ? master_lower : slave_lower;
            const double *upper = side ? master_upper : slave_upper;
            for (long i = 0; i < group->count; ++i) {
                long b = group->members[i] * dim;
                for (int k = 0; k < dim; ++k) {
                    double c = cell(lower + b, upper + b, k, width[k]);
                    if (c < low[k]) low[k] = c;
                    if (c > high[k]) high[k] = c;
                }
            }
        }
        int widest = 0;
        for (int k = 0; k < dim; ++k) {
            extent[k] = high[k] - low[k] + 3.0;
            cells *= extent[k];
            if (extent[k] > extent[widest]) widest = k;
        }
        if (cells < 4.0e18) break;
        width[widest] *= 2.0;
    }
    long stride[3];
    stride[dim - 1] = 1;
    for (int k = dim - 2; k >= 0; --k) stride[k] = stride[k + 1] * (long)extent[k + 1];
    for (long i = 0; i < masters->count; ++i) {
        long m = masters->members[i], key = 0;
        for (int k = 0; k < dim; ++k)
            key += (long)(cell(master_lower + m * dim, master_upper + m * dim, k, width[k])
                          - low[k] + 1.0) * stride[k];
        sorted[i].key = key;
        sorted[i].index = m;
    }
    qsort(sorted, (size_t)masters->count, sizeof(keyed_t), compare_keyed);
    int num_columns = dim == 3 ? 9 : (dim == 2 ? 3 : 1);
    for (long i = 0; i < slaves->count; ++i) {
        long s = slaves->members[i], centre = 0;
        const double *lower = slave_lower + s * dim, *upper = slave_upper + s * dim;
        for (int k = 0; k < dim; ++k)
            centre += (long)(cell(lower, upper, k, width[k]) - low[k] + 1.0) * stride[k];
        for (int column = 0; column < num_columns; ++column) {
            /* the neighbours along the last coordinate are consecutive keys */
            long first = centre - 1;
            if (dim >= 2) first += (column % 3 - 1) * stride[dim - 2];
            if (dim == 3) first += (column / 3 - 1) * stride[0];
            long a = 0, b = masters->count;
            while (a < b) {
                long mid = a + (b - a) / 2;
                if (sorted[mid].key < first) a = mid + 1;
                else b = mid;
            }
            for (; a < masters->count && sorted[a].key <= first + 2; ++a) {
                long m = sorted[a].index;
                ++*tested;
                if (boxes_overlap(dim, lower, upper, master_lower + m * dim,
                                  master_upper + m * dim, margin)
                    && push(found, s, m))
                    return -1;
            }
        }
    }
    return 0;
}

/* Every (slave, master) pair of boxes (lower, upper: (n, dim) each) that overlap once each is
 * grown by margin, sorted by slave then master, in *pairs ((*num_pairs, 2), allocated here:
 * give it back with search_free). *tested counts the box tests done. Boxes are grouped by
 * size (within a factor 2) and each pair of groups has its own grid, so that the few long
 * boxes of nodes that moved far do not coarsen the search of all the others. Returns 0, or
 * -1 if out of memory. */
int search_boxes(long ns, long nm, int dim, const double *slave_lower,
                 const double *slave_upper, const double *master_lower,
                 const double *master_upper, double margin, long **pairs, long *num_pairs,
                 long *tested) {
    group_t *slave_groups = NULL, *master_groups = NULL;
    long *slave_members = NULL, *master_members = NULL, *start = NULL, *scratch = NULL;
    keyed_t *sorted = NULL;
    pairs_t found = {NULL, 0, 0};
    int status = -1;
    *pairs = NULL;
    *num_pairs = *tested = 0;
    if (dim < 1 || dim > 3) return -1;
    int num_slave_groups = group_boxes(ns, dim, slave_lower, slave_upper, margin,
                                       &slave_groups, &slave_members);
    int num_master_groups = group_boxes(nm, dim, master_lower, master_upper, margin,
                                        &master_groups, &master_members);
    sorted = malloc(sizeof(keyed_t) * (size_t)(nm > 0 ? nm : 1));
    start = calloc((size_t)ns + 1, sizeof(long));
    if (num_slave_groups < 0 || num_master_groups < 0 || !sorted || !start) goto done;
    for (int a = 0; a < num_slave_groups; ++a)
        for (int b = 0; b < num_master_groups; ++b)
            if (pair_groups(dim, slave_groups + a, master_groups + b, slave_lower, slave_upper,
                            master_lower, master_upper, margin, sorted, &found, tested))
                goto done;
    /* by slave (counting), then by master within each slave */
    *pairs = malloc(sizeof(long) * 2 * (size_t)(found.size > 0 ? found.size : 1));
    if (!*pairs) goto done;
    for (long p = 0; p < found.size; ++p) ++start[found.data[2 * p] + 1];
    for (long s = 0; s < ns; ++s) start[s + 1] += start[s];
    for (long p = 0; p < found.size; ++p) {
        long s = found.data[2 * p];
        (*pairs)[2 * start[s]] = s;
        (*pairs)[2 * start[s] + 1] = found.data[2 * p + 1];
        ++start[s];
    }
    /* start[s] is now the end of slave s's pairs */
    long most = 0;
    for (long s = 0, begin = 0; s < ns; begin = start[s++])
        if (start[s] - begin > most) most = start[s] - begin;
    scratch = malloc(sizeof(long) * (size_t)(most > 0 ? most : 1));
    if (!scratch) goto done;
    for (long s = 0, begin = 0; s < ns; begin = start[s++]) {
        long count = start[s] - begin;
        for (long p = 0; p < count; ++p) scratch[p] = (*pairs)[2 * (begin + p) + 1];
        if (count > 16) {
            qsort(scratch, (size_t)count, sizeof(long), compare_long);
        } else {
            for (long p = 1; p < count; ++p) {
                long master = scratch[p], q = p;
                for (; q > 0 && scratch[q - 1] > master; --q) scratch[q] = scratch[q - 1];
                scratch[q] = master;
            }
        }
        for (long p = 0; p < count; ++p) (*pairs)[2 * (begin + p) + 1] = scratch[p];
    }
    *num_pairs = found.size;
    status = 0;
done:
    if (status) {
        free(*pairs);
        *pairs = NULL;
    }
    free(found.data);
    free(slave_groups);
    free(master_groups);
    free(slave_members);
    free(master_members);
    free(sorted);
    free(start);
    free(scratch);
    return status;
}

void search_free(long *pairs) { free(pairs); }
