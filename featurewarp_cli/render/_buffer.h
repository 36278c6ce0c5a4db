/* The buffer check of featurewarp's C rasterizer (_raster.c). */
#ifndef FEATUREWARP_BUFFER_H
#define FEATUREWARP_BUFFER_H

#include <Python.h>
#include <string.h>

/* A C-contiguous buffer of items of `itemsize` bytes (any size when 0) whose struct format
 * code is among `codes`; -1 with a TypeError otherwise. */
static int
get(PyObject *obj, Py_buffer *view, const char *codes, Py_ssize_t itemsize, int writable,
    const char *name)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0)
        return -1;
    const char *f = view->format ? view->format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    if ((itemsize && view->itemsize != itemsize) || f[0] == '\0' || f[1] != '\0' || !strchr(codes, f[0])) {
        PyErr_Format(PyExc_TypeError, "%s: expected items of %zd bytes ('%s'), got '%s'",
                     name, itemsize, codes, view->format ? view->format : "B");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

#endif
