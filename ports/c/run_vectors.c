/* The host's vector runner: mrs_vectors_main() (mrs_vectors.h) as a program. */
#include <stddef.h>

#include "mrs_vectors.h"

int main(int argc, char **argv)
{
    return mrs_vectors_main(argc, argv, NULL);
}
