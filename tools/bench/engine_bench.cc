namespace imr::bench {
int RunEngineBench(int, char**) { return 0; }
}
